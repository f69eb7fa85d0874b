//! Tests of the check's plan, report, table and JSON, and of its cheap stages on flex.

use super::*;

fn adapter(kind: AdapterKind) -> AdapterInfo {
    AdapterInfo {
        name: "llvmpipe (LLVM 15.0.6, 256 bits)".into(),
        kind,
        backend: "Vulkan".into(),
        driver: "llvmpipe".into(),
        driver_info: "Mesa 22.3.6".into(),
    }
}

#[test]
fn the_plan_is_paper_on_a_gpu_and_tiny_on_a_cpu_adapter() {
    for kind in [
        AdapterKind::DiscreteGpu,
        AdapterKind::IntegratedGpu,
        AdapterKind::VirtualGpu,
        AdapterKind::Other,
    ] {
        let p = plan_training(kind, None, None);
        assert_eq!((p.preset, p.iterations), (Preset::Paper, 30), "{kind:?}");
        assert!(p.reason.contains("GPU"), "{}", p.reason);
    }
    let p = plan_training(AdapterKind::Cpu, None, None);
    assert_eq!((p.preset, p.iterations), (Preset::Tiny, 3));
    assert!(p.reason.contains("CPU") && p.reason.contains("hours"));
    // What the user asks for wins, and the reason says so.
    let p = plan_training(AdapterKind::Cpu, Some(Preset::Quick), None);
    assert_eq!((p.preset, p.iterations), (Preset::Quick, 3));
    assert!(p.reason.starts_with("--preset as given"), "{}", p.reason);
    let p = plan_training(AdapterKind::DiscreteGpu, None, Some(5));
    assert_eq!((p.preset, p.iterations), (Preset::Paper, 5));
    assert!(
        p.reason.starts_with("--iterations as given"),
        "{}",
        p.reason
    );
    let p = plan_training(AdapterKind::Cpu, Some(Preset::Paper), Some(1));
    assert_eq!((p.preset, p.iterations), (Preset::Paper, 1));
    assert_eq!(p.reason, "--preset and --iterations as given");
}

#[test]
fn stages_report_errors_and_panics_as_failures() {
    let good = run_stage("good", || {
        Ok(StageOutcome {
            summary: "fine".into(),
            data: serde_json::json!({"x": 1}),
            problem: None,
        })
    });
    assert_eq!(good.status, StageStatus::Ok);
    assert_eq!(good.error, None);
    assert_eq!(good.data["x"], 1);
    let off = run_stage("off", || {
        Ok(StageOutcome {
            summary: "numbers".into(),
            data: serde_json::json!({"x": 2}),
            problem: Some("too far".into()),
        })
    });
    assert_eq!(off.status, StageStatus::Failed);
    assert_eq!(off.error.as_deref(), Some("too far"));
    assert_eq!(off.summary, "numbers");
    assert_eq!(off.data["x"], 2);
    let err = run_stage("err", || {
        Err(BittError::Invalid("no adapter memory".into()))
    });
    assert_eq!(err.status, StageStatus::Failed);
    assert_eq!(err.error.as_deref(), Some("no adapter memory"));
    assert_eq!(err.data, serde_json::Value::Null);
    let panicked = run_stage("panic", || panic!("device lost: {}", 3));
    assert_eq!(panicked.status, StageStatus::Failed);
    assert_eq!(panicked.error.as_deref(), Some("panicked: device lost: 3"));
}

fn report() -> GpuCheckReport {
    let stage = |name: &str, ok: bool| StageReport {
        name: name.into(),
        status: if ok {
            StageStatus::Ok
        } else {
            StageStatus::Failed
        },
        seconds: 1.25,
        summary: if ok { "all good".into() } else { String::new() },
        error: (!ok).then(|| "out of memory".to_string()),
        data: serde_json::json!({"seconds_per_iteration": 0.5}),
    };
    GpuCheckReport {
        adapter: adapter(AdapterKind::Cpu),
        reference: "flex".into(),
        cores: 2,
        plan: plan_training(AdapterKind::Cpu, None, None),
        stages: vec![stage("backend-check", true), stage("training", false)],
        seconds: 12.5,
    }
}

#[test]
fn the_table_names_the_adapter_the_plan_and_every_stage() {
    let r = report();
    assert_eq!(r.failed(), 1);
    let table = r.table();
    let lines: Vec<&str> = table.lines().collect();
    assert_eq!(
        lines[0],
        "bitt gpu-check: wgpu against flex (2 cores), 12.5 s"
    );
    assert_eq!(
        lines[1],
        "adapter   llvmpipe (LLVM 15.0.6, 256 bits) (CPU (software rendering); Vulkan; \
         driver llvmpipe Mesa 22.3.6)"
    );
    assert!(lines[2].starts_with("training  tiny preset, 3 iterations (the adapter is a CPU"));
    assert_eq!(lines[4], "stage          status   seconds  result");
    assert_eq!(lines[5], "backend-check  ok          1.25  all good");
    assert_eq!(lines[6], "training       FAILED      1.25  ");
    assert_eq!(lines[7], "               error: out of memory");
    assert_eq!(*lines.last().unwrap(), "1 ok, 1 failed");
}

#[test]
fn the_json_holds_the_adapter_plan_and_stage_numbers() {
    let v = serde_json::to_value(report()).unwrap();
    assert_eq!(v["adapter"]["kind"], "cpu");
    assert_eq!(v["adapter"]["name"], "llvmpipe (LLVM 15.0.6, 256 bits)");
    assert_eq!(v["plan"]["preset"], "tiny");
    assert_eq!(v["plan"]["iterations"], 3);
    assert_eq!(v["stages"][0]["status"], "ok");
    assert_eq!(v["stages"][1]["status"], "failed");
    assert_eq!(v["stages"][1]["error"], "out of memory");
    assert_eq!(v["stages"][1]["data"]["seconds_per_iteration"], 0.5);
    assert_eq!(v["seconds"], 12.5);
    // The adapter's kind reads back.
    let a: AdapterInfo = serde_json::from_value(v["adapter"].clone()).unwrap();
    assert_eq!(a, adapter(AdapterKind::Cpu));
}

#[test]
fn training_time_is_projected_from_the_iterations_after_the_first() {
    assert_eq!(stages::projected_seconds(&[]), None);
    assert_eq!(
        stages::projected_seconds(&[4.0]),
        Some((4.0, 4.0, 4.0 * 700.0))
    );
    let (first, steady, total) = stages::projected_seconds(&[10.0, 1.0, 2.0, 3.0]).unwrap();
    assert_eq!((first, steady), (10.0, 2.0));
    assert_eq!(total, 10.0 + 2.0 * 699.0);
}

#[test]
fn cheap_stages_agree_on_flex() {
    let flex = Device::flex();
    let b = stages::backend_check(&flex, &flex).unwrap();
    assert_eq!(b.problem, None);
    assert_eq!(b.data["max_abs_diff"], 0.0);
    assert_eq!(b.data["values"], 442);
    let r = stages::raster_comparison(&flex).unwrap();
    assert_eq!(r.problem, None, "{}", r.summary);
    assert_eq!(r.data["kernel"], "Host");
    assert_eq!(r.data["face_ids_differing"], 0);
    assert_eq!(r.data["image"], serde_json::json!([256, 256]));
    // The demo scene's hands at 256x256 (the README's render benchmark counts the same).
    assert_eq!(r.data["covered_pixels"], 17_410);
    // The host path reads the clip positions back once.
    assert_eq!(r.data["host_readbacks"], 1);
}

#[test]
fn the_dense_rasterizer_stage_runs_the_kernel_on_wgpu_without_readbacks() {
    let Some(wgpu) = bitt_testkit::wgpu() else {
        eprintln!(
            "SKIPPED the_dense_rasterizer_stage_runs_the_kernel_on_wgpu_without_readbacks: no wgpu adapter"
        );
        return;
    };
    let r = stages::raster_comparison(&wgpu).unwrap();
    assert_eq!(r.problem, None, "{}", r.summary);
    assert_eq!(r.data["kernel"], "Cube");
    assert_eq!(r.data["host_reason"], serde_json::Value::Null);
    assert_eq!(r.data["host_readbacks"], 0);
    assert_eq!(r.data["face_ids_differing"], 0);
    assert_eq!(r.data["covered_pixels"], 17_410);
}
