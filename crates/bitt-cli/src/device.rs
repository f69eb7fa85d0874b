//! Choosing a burn device by name (binaries only; libraries take `&Device`).

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
            DeviceName::Wgpu => Device::wgpu(DeviceKind::DefaultDevice),
            DeviceName::Cuda => cuda()?,
        })
    }
}

#[cfg(feature = "cuda")]
fn cuda() -> anyhow::Result<Device> {
    Ok(Device::cuda(0))
}

#[cfg(not(feature = "cuda"))]
fn cuda() -> anyhow::Result<Device> {
    anyhow::bail!("this `bitt` was built without CUDA; rebuild with `--features cuda`")
}
