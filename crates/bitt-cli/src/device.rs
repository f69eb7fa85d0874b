//! Choosing a burn device by name (binaries only; libraries take `&Device`).

use std::sync::OnceLock;

use bitt_bench::gpu_check::AdapterInfo;
use burn::tensor::{Device, DeviceKind};

/// The backends this binary is built with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DeviceName {
    /// burn's pure-Rust CPU backend (the CPU default).
    Flex,
    /// burn's ndarray CPU backend (deprecated upstream; small checks only).
    Ndarray,
    /// wgpu on the best adapter present (Vulkan, Metal, or Mesa's software Vulkan).
    Wgpu,
    /// CUDA (builds with `--features cuda` only).
    Cuda,
}

impl DeviceName {
    /// The burn device, or an error when this build lacks the backend.
    pub fn device(self) -> anyhow::Result<Device> {
        Ok(match self {
            DeviceName::Flex => Device::flex(),
            #[allow(deprecated)]
            DeviceName::Ndarray => Device::ndarray(),
            DeviceName::Wgpu => wgpu()?,
            DeviceName::Cuda => cuda()?,
        })
    }
}

/// The wgpu device, set up once per process, its adapter named on stderr.
fn wgpu() -> anyhow::Result<Device> {
    wgpu_with_adapter().map(|(device, _)| device)
}

/// The wgpu device and its adapter, set up once per process, the adapter named on stderr.
///
/// Off macOS the graphics API is pinned to Vulkan (a GPU's driver, or Mesa's lavapipe):
/// `Auto` would go on to set up OpenGL (EGL) and others when Vulkan has only a software
/// adapter. Where Vulkan has no adapter at all, `Auto` chooses.
pub fn wgpu_with_adapter() -> anyhow::Result<(Device, AdapterInfo)> {
    static WGPU: OnceLock<Result<(Device, AdapterInfo), String>> = OnceLock::new();
    WGPU.get_or_init(|| {
        use burn::tensor::wgpu::WgpuBackend;
        let pinned = if cfg!(target_os = "macos") {
            Err("Metal is chosen by Auto".to_string())
        } else {
            Device::wgpu_options()
                .device_kind(DeviceKind::DefaultDevice)
                .graphics_api(WgpuBackend::Vulkan)
                .init_with_setup()
                .map_err(|e| e.to_string())
        };
        let (device, setup) = match pinned {
            Ok(found) => found,
            Err(vulkan) => Device::wgpu_options()
                .device_kind(DeviceKind::DefaultDevice)
                .init_with_setup()
                .map_err(|e| format!("no wgpu adapter: {e} (Vulkan: {vulkan})"))?,
        };
        let info = AdapterInfo::from_wgpu(&setup.adapter.get_info(), setup.backend);
        eprintln!("wgpu adapter: {}", info.describe());
        Ok((device, info))
    })
    .clone()
    .map_err(|e| anyhow::anyhow!(e))
}

#[cfg(feature = "cuda")]
fn cuda() -> anyhow::Result<Device> {
    Ok(Device::cuda(0))
}

#[cfg(not(feature = "cuda"))]
fn cuda() -> anyhow::Result<Device> {
    anyhow::bail!("this `bitt` was built without CUDA; rebuild with `--features cuda`")
}
