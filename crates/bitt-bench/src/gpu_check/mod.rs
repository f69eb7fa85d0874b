//! `bitt gpu-check`: one run of every GPU-relevant check on a wgpu device against the host
//! backend, each stage reporting ok or failed on its own, gathered into one report (a
//! printed table and JSON).
//!
//! The stages ([`stages`]): the backend check ([`crate::backend_check`]) and the demo render
//! on the device against the host; `rasterize_dense` on the device against the CPU core
//! (face ids, kernel, host readbacks); training on the demo scene (seconds per iteration,
//! projected to the paper's 700 iterations); the BTR and albedo benches. Which preset trains
//! depends on the adapter ([`plan_training`]): `paper` on a GPU, `tiny` on a CPU adapter
//! (Mesa's lavapipe), where `paper` would take hours.
//!
//! The caller picks the devices and names the adapter; nothing here chooses a device.

pub mod stages;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Instant;

use bitt_nets::Preset;
use burn::tensor::Device;

use crate::nets_bench::BenchedNet;
use bitt::BittError;

/// Training iterations on a GPU adapter unless told otherwise.
pub(crate) const GPU_ITERATIONS: usize = 30;
/// Training iterations on a CPU adapter unless told otherwise.
pub(crate) const CPU_ADAPTER_ITERATIONS: usize = 3;
/// The paper's iterations per scene, which the training time is projected to.
pub(crate) const PAPER_ITERATIONS: usize = 700;

/// What kind of device the adapter is (wgpu's `DeviceType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AdapterKind {
    /// A GPU of its own.
    DiscreteGpu,
    /// A GPU sharing the CPU's memory.
    IntegratedGpu,
    /// A virtualised GPU.
    VirtualGpu,
    /// Software on the CPU (Mesa's lavapipe / llvmpipe).
    Cpu,
    /// The driver did not say.
    Other,
}

impl AdapterKind {
    /// Words for the table.
    pub fn describe(self) -> &'static str {
        match self {
            AdapterKind::DiscreteGpu => "discrete GPU",
            AdapterKind::IntegratedGpu => "integrated GPU",
            AdapterKind::VirtualGpu => "virtual GPU",
            AdapterKind::Cpu => "CPU (software rendering)",
            AdapterKind::Other => "unknown type",
        }
    }
}

/// The wgpu adapter the check ran on, as the caller found it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct AdapterInfo {
    /// The adapter's name (`NVIDIA H200`, `llvmpipe (LLVM 15.0.6, 256 bits)`).
    pub name: String,
    /// Its kind.
    pub kind: AdapterKind,
    /// The graphics API (`Vulkan`, `Metal`, ...).
    pub backend: String,
    /// The driver's name.
    pub driver: String,
    /// The driver's version text.
    pub driver_info: String,
}

impl AdapterInfo {
    /// What wgpu says of an adapter, and the graphics API it was opened with.
    pub fn from_wgpu(
        info: &burn::tensor::wgpu::wgpu::AdapterInfo,
        backend: impl std::fmt::Debug,
    ) -> Self {
        use burn::tensor::wgpu::wgpu::DeviceType;
        Self {
            name: info.name.clone(),
            kind: match info.device_type {
                DeviceType::DiscreteGpu => AdapterKind::DiscreteGpu,
                DeviceType::IntegratedGpu => AdapterKind::IntegratedGpu,
                DeviceType::VirtualGpu => AdapterKind::VirtualGpu,
                DeviceType::Cpu => AdapterKind::Cpu,
                DeviceType::Other => AdapterKind::Other,
            },
            backend: format!("{backend:?}"),
            driver: info.driver.clone(),
            driver_info: info.driver_info.clone(),
        }
    }

    /// One line: name, kind, API and driver.
    pub fn describe(&self) -> String {
        format!(
            "{} ({}; {}; driver {} {})",
            self.name,
            self.kind.describe(),
            self.backend,
            self.driver,
            self.driver_info
        )
    }
}

/// What the training stage runs, and why.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TrainingPlan {
    /// The preset of the training stage and of the network benches.
    pub preset: Preset,
    /// Training iterations.
    pub iterations: usize,
    /// Why this preset and this many iterations.
    pub reason: String,
}

/// The preset and iterations of the training stage: what the caller asked for, else
/// `paper` for [`GPU_ITERATIONS`] on a GPU and `tiny` for [`CPU_ADAPTER_ITERATIONS`] on a CPU
/// adapter (software Vulkan runs `paper` for hours).
pub fn plan_training(
    kind: AdapterKind,
    preset: Option<Preset>,
    iterations: Option<usize>,
) -> TrainingPlan {
    let cpu = kind == AdapterKind::Cpu;
    let (default_preset, default_iterations) = if cpu {
        (Preset::Tiny, CPU_ADAPTER_ITERATIONS)
    } else {
        (Preset::Paper, GPU_ITERATIONS)
    };
    let why_default = if cpu {
        "the adapter is a CPU (software rendering), where paper would take hours"
    } else {
        "the adapter is a GPU"
    };
    let reason = match (preset, iterations) {
        (None, None) => format!("{why_default}: the default for it"),
        (Some(_), None) => format!("--preset as given; iterations: {why_default}"),
        (None, Some(_)) => format!("--iterations as given; preset: {why_default}"),
        (Some(_), Some(_)) => "--preset and --iterations as given".to_string(),
    };
    TrainingPlan {
        preset: preset.unwrap_or(default_preset),
        iterations: iterations.unwrap_or(default_iterations),
        reason,
    }
}

/// Whether a stage passed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StageStatus {
    /// It ran and its results are within tolerance.
    Ok,
    /// It returned an error, panicked, or its results are out of tolerance.
    Failed,
}

/// What a stage computed: one line for the table, the numbers for the JSON, and what is
/// wrong with them (`None` when nothing is).
#[derive(Debug, Clone, PartialEq)]
pub struct StageOutcome {
    /// One line for the table.
    pub summary: String,
    /// The stage's numbers.
    pub data: serde_json::Value,
    /// Results out of tolerance (the stage then fails, numbers kept).
    pub problem: Option<String>,
}

/// One stage's result.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StageReport {
    /// The stage's name (`backend-check`, `render`, ...).
    pub name: String,
    /// Ok or failed.
    pub status: StageStatus,
    /// Wall-clock seconds of the stage.
    pub seconds: f64,
    /// One line of results (empty when the stage errored before any).
    pub summary: String,
    /// Why it failed.
    pub error: Option<String>,
    /// The stage's numbers (`null` when it errored).
    pub data: serde_json::Value,
}

impl StageReport {
    /// The stage's progress line: `gpu-check NAME: ok (S s)` or `FAILED (S s): why`.
    pub fn progress_line(&self) -> String {
        match self.status {
            StageStatus::Ok => format!("gpu-check {}: ok ({:.1} s)", self.name, self.seconds),
            StageStatus::Failed => format!(
                "gpu-check {}: FAILED ({:.1} s): {}",
                self.name,
                self.seconds,
                self.error.as_deref().unwrap_or("")
            ),
        }
    }
}

/// The whole check.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GpuCheckReport {
    /// The device's adapter.
    pub adapter: AdapterInfo,
    /// The reference backend (`flex`).
    pub reference: String,
    /// CPU cores the host backend may use.
    pub cores: usize,
    /// What the training stage runs.
    pub plan: TrainingPlan,
    /// Every stage, in the order run.
    pub stages: Vec<StageReport>,
    /// Wall-clock seconds of all stages.
    pub seconds: f64,
}

impl GpuCheckReport {
    /// Stages that failed.
    pub fn failed(&self) -> usize {
        self.stages
            .iter()
            .filter(|s| s.status == StageStatus::Failed)
            .count()
    }

    /// The table printed at the end: the adapter, the plan, one row per stage (failed
    /// stages with their error on the next line) and the count.
    pub fn table(&self) -> String {
        let mut out = String::new();
        out.push_str(&format!(
            "bitt gpu-check: wgpu against {} ({} cores), {:.1} s\n",
            self.reference, self.cores, self.seconds
        ));
        out.push_str(&format!("adapter   {}\n", self.adapter.describe()));
        out.push_str(&format!(
            "training  {} preset, {} iterations ({})\n\n",
            self.plan.preset, self.plan.iterations, self.plan.reason
        ));
        let width = self
            .stages
            .iter()
            .map(|s| s.name.len())
            .max()
            .unwrap_or(5)
            .max(5);
        out.push_str(&format!(
            "{:width$}  {:6}  {:>8}  result\n",
            "stage", "status", "seconds"
        ));
        for s in &self.stages {
            let status = match s.status {
                StageStatus::Ok => "ok",
                StageStatus::Failed => "FAILED",
            };
            out.push_str(&format!(
                "{:width$}  {:6}  {:>8.2}  {}\n",
                s.name, status, s.seconds, s.summary
            ));
            if let Some(e) = &s.error {
                out.push_str(&format!("{:width$}  error: {e}\n", ""));
            }
        }
        let failed = self.failed();
        out.push_str(&format!(
            "\n{} ok, {failed} failed\n",
            self.stages.len() - failed
        ));
        out
    }
}

/// Runs `stage`, timing it and turning an error or a panic into a failed report.
pub(crate) fn run_stage(
    name: &str,
    stage: impl FnOnce() -> Result<StageOutcome, BittError>,
) -> StageReport {
    let start = Instant::now();
    let result = catch_unwind(AssertUnwindSafe(stage));
    let seconds = start.elapsed().as_secs_f64();
    let (summary, data, error) = match result {
        Ok(Ok(o)) => (o.summary, o.data, o.problem),
        Ok(Err(e)) => (String::new(), serde_json::Value::Null, Some(e.to_string())),
        Err(panic) => {
            let message = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| (*s).to_string()))
                .unwrap_or_else(|| "a panic without a message".to_string());
            (
                String::new(),
                serde_json::Value::Null,
                Some(format!("panicked: {message}")),
            )
        }
    };
    StageReport {
        name: name.to_string(),
        status: if error.is_some() {
            StageStatus::Failed
        } else {
            StageStatus::Ok
        },
        seconds,
        summary,
        error,
        data,
    }
}

/// The devices of a check: `device` (wgpu) is checked against `host` (flex), which also
/// generates the scene and the texture model on all cores.
#[derive(Debug, Clone)]
pub struct CheckDevices {
    /// The device under test (plain; autodiff is added where needed).
    pub device: Device,
    /// The reference and host backend.
    pub host: Device,
    /// The reference's name in the report (`flex`).
    pub host_name: String,
    /// The device's adapter.
    pub adapter: AdapterInfo,
}

/// Runs every stage in turn, calling `on_stage` after each, and gathers the report.
pub fn run_check(
    devices: &CheckDevices,
    plan: &TrainingPlan,
    on_stage: &mut dyn FnMut(&StageReport),
) -> GpuCheckReport {
    let start = Instant::now();
    let (device, host) = (&devices.device, &devices.host);
    let mut reports = Vec::new();
    let mut stage = |name: &str, f: &dyn Fn() -> Result<StageOutcome, BittError>| {
        let r = run_stage(name, f);
        on_stage(&r);
        reports.push(r);
    };
    stage("backend-check", &|| stages::backend_check(device, host));
    stage("render", &|| stages::render_comparison(device, host));
    stage("rasterize-dense", &|| stages::raster_comparison(device));
    stage("training", &|| stages::training(device, host, plan));
    stage("bench btr", &|| {
        stages::net_bench(device, BenchedNet::Btr, plan.preset)
    });
    stage("bench albedo", &|| {
        stages::net_bench(device, BenchedNet::Albedo, plan.preset)
    });
    GpuCheckReport {
        adapter: devices.adapter.clone(),
        reference: devices.host_name.clone(),
        cores: std::thread::available_parallelism().map_or(1, usize::from),
        plan: plan.clone(),
        stages: reports,
        seconds: start.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests;
