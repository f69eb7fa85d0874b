//! `bitt gpu-check`: arguments, the wgpu and flex devices, progress lines and the final
//! table of [`bitt_bench::gpu_check`], written as JSON into `--out`.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use bitt_bench::gpu_check::{AdapterKind, CheckDevices, StageReport, plan_training, run_check};
use bitt_nets::Preset;
use burn::tensor::Device;

/// The JSON file the report is written to, inside `--out`.
pub const REPORT_FILE: &str = "gpu-check.json";

/// Arguments of `bitt gpu-check`.
#[derive(Debug, clap::Args)]
pub struct GpuCheckArgs {
    /// Folder to write gpu-check.json into (created if missing).
    #[arg(long, default_value = "gpu-check")]
    pub out: PathBuf,
    /// Training iterations (default: 30 on a GPU, 3 on a CPU adapter such as lavapipe).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Preset of the training stage and the network benches (default: paper on a GPU, tiny
    /// on a CPU adapter).
    #[arg(long)]
    pub preset: Option<Preset>,
}

/// What to do when wgpu finds no adapter (the error names this).
const NO_ADAPTER_HELP: &str = "bitt gpu-check needs a Vulkan adapter. On an NVIDIA machine the \
driver's Vulkan ICD (nvidia_icd.json and libGLX_nvidia.so) comes into a container only with the \
`graphics` driver capability (NVIDIA_DRIVER_CAPABILITIES=all or compute,utility,graphics); a \
container with `compute,utility` alone has CUDA but no Vulkan adapter. Elsewhere, install a \
Vulkan driver (Mesa's lavapipe, package mesa-vulkan-drivers, is a CPU one)";

/// `bitt gpu-check`.
pub fn run(args: &GpuCheckArgs) -> Result<()> {
    if args.iterations == Some(0) {
        bail!("--iterations must be at least 1");
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("--out {}: cannot create the folder", args.out.display()))?;
    let (device, adapter) = crate::device::wgpu_with_adapter()
        .map_err(|e| anyhow::anyhow!("{e:#}\n{NO_ADAPTER_HELP}"))?;
    // Off macOS the check is of Vulkan: wgpu's fallback (OpenGL through EGL, usually Mesa's
    // llvmpipe) would measure something else.
    if !cfg!(target_os = "macos") && adapter.backend != "Vulkan" {
        bail!(
            "wgpu found no Vulkan adapter (it fell back to {}, {}).\n{NO_ADAPTER_HELP}",
            adapter.backend,
            adapter.name
        );
    }
    if adapter.kind == AdapterKind::Cpu {
        eprintln!(
            "note: the Vulkan adapter is a CPU ({}); on a GPU machine this means the GPU's \
             Vulkan driver is not visible, e.g. a container without the `graphics` driver \
             capability",
            adapter.name
        );
    }
    let plan = plan_training(adapter.kind, args.preset, args.iterations);
    eprintln!(
        "gpu-check on {}: training {} x {} ({})",
        adapter.describe(),
        plan.preset,
        plan.iterations,
        plan.reason
    );
    let devices = CheckDevices {
        device,
        host: Device::flex(),
        host_name: "flex".into(),
        adapter,
    };
    let report = run_check(&devices, &plan, &mut |r: &StageReport| {
        eprintln!("{}", r.progress_line());
    });
    let path = args.out.join(REPORT_FILE);
    let text = serde_json::to_string_pretty(&report)?;
    let written =
        std::fs::write(&path, text + "\n").with_context(|| format!("writing {}", path.display()));
    println!("\n{}", report.table());
    written?;
    println!("wrote {}", path.display());
    let failed = report.failed();
    if failed > 0 {
        bail!("{failed} of {} stages failed", report.stages.len());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    type Cli = crate::test_args::Parsed<GpuCheckArgs>;

    #[test]
    fn arguments_default_to_the_adapter_s_plan() {
        let a = Cli::try_parse_from(["bitt"]).unwrap().args;
        assert_eq!(a.out, PathBuf::from("gpu-check"));
        assert_eq!((a.iterations, a.preset), (None, None));
        let a = Cli::try_parse_from([
            "bitt",
            "--out",
            "/tmp/x",
            "--iterations",
            "7",
            "--preset",
            "quick",
        ])
        .unwrap()
        .args;
        assert_eq!(a.out, PathBuf::from("/tmp/x"));
        assert_eq!((a.iterations, a.preset), (Some(7), Some(Preset::Quick)));
        assert!(Cli::try_parse_from(["bitt", "--preset", "huge"]).is_err());
    }

    #[test]
    fn zero_iterations_are_refused_before_any_device_is_touched() {
        let dir = std::env::temp_dir().join(format!("bitt-gpu-check-{}", std::process::id()));
        let a = Cli::try_parse_from(["bitt", "--iterations", "0", "--out", dir.to_str().unwrap()])
            .unwrap()
            .args;
        let e = format!("{:#}", run(&a).unwrap_err());
        assert_eq!(e, "--iterations must be at least 1");
        assert!(!dir.exists());
    }
}
