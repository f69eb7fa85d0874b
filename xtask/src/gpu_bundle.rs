//! `cargo xtask gpu-bundle` (the stripped, gzipped `bitt` of the `gpu` profile, the Vulkan
//! loader and a `run.sh`, for GPU machines without network) and `cargo xtask gpu-check` (that
//! bundle run here, on whatever Vulkan adapter exists: lavapipe on a CPU-only machine).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result, bail};

use crate::{build_bitt_gpu, check, root, runtime_dir};

/// The bundle's folder at the repository root (ignored by git).
pub const BUNDLE_DIR: &str = "gpu-bundle";
/// What may travel to a GPU machine.
const MAX_BUNDLE_BYTES: u64 = 64 * 1024 * 1024;
/// The Vulkan loader's file name, as wgpu opens it.
const VULKAN_LOADER: &str = "libvulkan.so.1";

/// The script that unpacks and runs `bitt gpu-check` on the target machine.
const RUN_SH: &str = r#"#!/bin/sh
# Runs `bitt gpu-check` from this folder, as written by `cargo xtask gpu-bundle`: unpacks
# bitt.gz (into $BITT_GPU_WORK, default ./work), puts the bundled Vulkan loader on
# LD_LIBRARY_PATH and passes its arguments on (default --out ./out). The Vulkan driver (ICD)
# is the machine's: NVIDIA's needs the container's `graphics` driver capability.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
work=${BITT_GPU_WORK:-$here/work}
mkdir -p "$work"
if [ ! -x "$work/bitt" ] || [ "$here/bitt.gz" -nt "$work/bitt" ]; then
    gzip -dc "$here/bitt.gz" > "$work/bitt.tmp"
    chmod +x "$work/bitt.tmp"
    mv "$work/bitt.tmp" "$work/bitt"
fi
export LD_LIBRARY_PATH="$here/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
case " $* " in
    *" --out "* | *" --out="*) ;;
    *) set -- --out "$here/out" "$@" ;;
esac
exec "$work/bitt" gpu-check "$@"
"#;

fn size_mib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

fn file_len(path: &Path) -> Result<u64> {
    Ok(std::fs::metadata(path)
        .with_context(|| format!("{} is missing", path.display()))?
        .len())
}

/// Copies the Vulkan loader into `lib`: the system's `libvulkan.so.1` (Debian's `libvulkan1`)
/// when installed, else the package downloaded with `apt-get download` and unpacked with
/// `dpkg-deb -x`. Returns where it came from.
fn vulkan_loader(lib: &Path) -> Result<String> {
    let dest = lib.join(VULKAN_LOADER);
    for dir in [
        "/usr/lib/x86_64-linux-gnu",
        "/lib/x86_64-linux-gnu",
        "/usr/lib64",
    ] {
        let candidate = Path::new(dir).join(VULKAN_LOADER);
        if let Ok(real) = std::fs::canonicalize(&candidate) {
            std::fs::copy(&real, &dest)
                .with_context(|| format!("copying {} to {}", real.display(), dest.display()))?;
            return Ok(real.display().to_string());
        }
    }
    let scratch = std::env::temp_dir().join(format!("bitt-libvulkan1-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&scratch);
    std::fs::create_dir_all(&scratch)?;
    let status = Command::new("apt-get")
        .args(["download", "libvulkan1"])
        .current_dir(&scratch)
        .status()
        .context("running apt-get download libvulkan1 (no libvulkan.so.1 on this system)")?;
    check(status, "apt-get download libvulkan1")?;
    let deb = std::fs::read_dir(&scratch)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "deb"))
        .context("apt-get download libvulkan1 wrote no .deb")?;
    let unpacked = scratch.join("root");
    let status = Command::new("dpkg-deb")
        .arg("-x")
        .arg(&deb)
        .arg(&unpacked)
        .status()
        .context("running dpkg-deb")?;
    check(status, "dpkg-deb -x")?;
    let real = std::fs::canonicalize(
        unpacked
            .join("usr/lib/x86_64-linux-gnu")
            .join(VULKAN_LOADER),
    )
    .with_context(|| format!("{} holds no {VULKAN_LOADER}", deb.display()))?;
    std::fs::copy(&real, &dest)?;
    let from = deb
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(from)
}

/// Builds `bitt` with the `gpu` profile (the GPU stack optimised) and writes the bundle;
/// returns its folder.
pub fn gpu_bundle() -> Result<PathBuf> {
    let start = Instant::now();
    let bin = build_bitt_gpu()?;
    let dir = root().join(BUNDLE_DIR);
    let lib = dir.join("lib");
    std::fs::create_dir_all(&lib).with_context(|| format!("creating {}", lib.display()))?;
    // Strip into the bundle's folder, then gzip (the binary keeps line tables for
    // backtraces; the GPU machine needs neither).
    let stripped = dir.join("bitt.stripped");
    let status = Command::new("strip")
        .arg("--strip-all")
        .arg("-o")
        .arg(&stripped)
        .arg(&bin)
        .status()
        .context("running strip (binutils)")?;
    check(status, "strip")?;
    let gz = dir.join("bitt.gz");
    let out = std::fs::File::create(&gz).with_context(|| format!("creating {}", gz.display()))?;
    let status = Command::new("gzip")
        .args(["-6", "-c"])
        .arg(&stripped)
        .stdout(out)
        .status()
        .context("running gzip")?;
    check(status, "gzip")?;
    let stripped_len = file_len(&stripped)?;
    std::fs::remove_file(&stripped)?;
    let loader_from = vulkan_loader(&lib)?;
    let run_sh = dir.join("run.sh");
    std::fs::write(&run_sh, RUN_SH)?;
    let status = Command::new("chmod").arg("+x").arg(&run_sh).status()?;
    check(status, "chmod +x run.sh")?;
    let parts = [gz.clone(), lib.join(VULKAN_LOADER), run_sh.clone()];
    let total: u64 = parts.iter().map(|p| file_len(p)).sum::<Result<u64>>()?;
    println!(
        "gpu-bundle: {} (binary {:.1} MiB with line tables, {:.1} MiB stripped, {:.1} MiB \
         gzipped; {VULKAN_LOADER} from {loader_from}, {:.2} MiB; total {:.1} MiB of {:.0} MiB; \
         {:.0} s)",
        dir.display(),
        size_mib(file_len(&bin)?),
        size_mib(stripped_len),
        size_mib(file_len(&gz)?),
        size_mib(file_len(&lib.join(VULKAN_LOADER))?),
        size_mib(total),
        size_mib(MAX_BUNDLE_BYTES),
        start.elapsed().as_secs_f64()
    );
    if total >= MAX_BUNDLE_BYTES {
        bail!(
            "the bundle is {:.1} MiB; at most {:.0} MiB travel to a GPU machine",
            size_mib(total),
            size_mib(MAX_BUNDLE_BYTES)
        );
    }
    Ok(dir)
}

/// `cargo xtask gpu-check [--reuse-bundle] [bitt gpu-check ARGS]`: writes the bundle (unless
/// `--reuse-bundle` finds one) and runs its `run.sh` here, printing the table; fails when
/// the check fails or its table does not name the adapter.
pub fn gpu_check(args: &[String]) -> Result<()> {
    let reuse = args.iter().any(|a| a == "--reuse-bundle");
    let rest: Vec<&String> = args.iter().filter(|a| *a != "--reuse-bundle").collect();
    let dir = root().join(BUNDLE_DIR);
    let dir = if reuse && dir.join("run.sh").is_file() && dir.join("bitt.gz").is_file() {
        dir
    } else {
        gpu_bundle()?
    };
    let start = Instant::now();
    let out = Command::new(dir.join("run.sh"))
        .args(&rest)
        .env("XDG_RUNTIME_DIR", runtime_dir())
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("running gpu-bundle/run.sh")?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    print!("{stdout}");
    let wall = start.elapsed().as_secs_f64();
    println!("gpu-check: run.sh took {wall:.0} s wall clock");
    if !stdout.lines().any(|l| l.starts_with("adapter ")) {
        bail!("bitt gpu-check printed no table naming the adapter");
    }
    check(out.status, "bitt gpu-check (run.sh)")
}
