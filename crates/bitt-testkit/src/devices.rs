//! The backends every numeric test runs on: flex, ndarray and, where an adapter exists, wgpu.

use std::io::Write;
use std::sync::OnceLock;

use burn::tensor::{Device, DeviceKind};

/// Set to `0` (or `false`, `off`, `no`) to leave wgpu out of [`devices`].
pub const WGPU_ENV: &str = "BITT_TEST_WGPU";

/// flex, ndarray and wgpu (see [`wgpu`]), plain (no autodiff), with their names.
pub fn devices() -> Vec<(&'static str, Device)> {
    let mut all = cpu_devices();
    all.extend(wgpu().map(|d| ("wgpu", d)));
    all
}

/// [`devices`] with autodiff.
pub fn autodiff_devices() -> Vec<(&'static str, Device)> {
    devices()
        .into_iter()
        .map(|(name, d)| (name, d.autodiff()))
        .collect()
}

/// flex and ndarray only: for tests too big for a software GPU, or about the CPU backends.
#[allow(deprecated)] // burn-ndarray is deprecated upstream but still a supported backend here
pub fn cpu_devices() -> Vec<(&'static str, Device)> {
    vec![("flex", Device::flex()), ("ndarray", Device::ndarray())]
}

/// The wgpu device, created once per process: Vulkan's default adapter (a GPU, or Mesa's
/// lavapipe), Metal's on macOS. `None`, after one line on stderr saying
/// `SKIPPED wgpu` and why, when no adapter can be created or [`WGPU_ENV`] is `0`.
pub fn wgpu() -> Option<Device> {
    static WGPU: OnceLock<Option<Device>> = OnceLock::new();
    WGPU.get_or_init(|| match init() {
        Ok(device) => Some(device),
        Err(why) => {
            // Straight to stderr, past the test harness's capture: once per process.
            let _ = writeln!(std::io::stderr(), "SKIPPED wgpu: {why}");
            None
        }
    })
    .clone()
}

fn init() -> Result<Device, String> {
    if let Ok(v) = std::env::var(WGPU_ENV)
        && matches!(v.trim(), "0" | "false" | "off" | "no")
    {
        return Err(format!("{WGPU_ENV}={v}"));
    }
    // A missing driver can panic inside wgpu rather than return an error.
    std::panic::catch_unwind(|| {
        use burn::tensor::wgpu::WgpuBackend;
        let options = Device::wgpu_options().device_kind(DeviceKind::DefaultDevice);
        // Off macOS, Vulkan only: `Auto` would go on to OpenGL (EGL) and its warnings.
        let options = if cfg!(target_os = "macos") {
            options
        } else {
            options.graphics_api(WgpuBackend::Vulkan)
        };
        options
            .init()
            .map_err(|e| format!("no Vulkan adapter ({e})"))
    })
    .unwrap_or_else(|_| Err("setting up wgpu panicked".to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The CPU backends come first, wgpu (where present) last, autodiff or not.
    #[test]
    fn the_list_starts_with_the_cpu_backends() {
        let names: Vec<_> = devices().into_iter().map(|(n, _)| n).collect();
        assert_eq!(names[..2], ["flex", "ndarray"]);
        assert!(names.len() == 2 || names[2..] == ["wgpu"], "{names:?}");
        let ad: Vec<_> = autodiff_devices().into_iter().map(|(n, _)| n).collect();
        assert_eq!(ad, names);
    }
}
