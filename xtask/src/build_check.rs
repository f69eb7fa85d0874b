//! `cargo xtask build-check`: the `bitt` binary alone and the test suite share one build of
//! every registry crate (burn, cubecl, wgpu, ...).
//!
//! `cargo xtask train-scene` builds only the binary (`-p bitt-cli --bin bitt`), `cargo xtask
//! test` every test of the workspace. Cargo reuses a compiled crate only when its features
//! and profile are the same, so a dependency that one side turns a feature on for (a
//! dev-dependency asking for `burn/std`, say) would make the tests rebuild burn after the
//! user's first build. This compares cargo's unit graphs (`--unit-graph`, read with
//! `RUSTC_BOOTSTRAP=1` as stable cargo has no other way to print them; nothing is built) and
//! fails naming every registry unit of the binary that the tests' and the examples' builds
//! would compile differently.

use std::collections::{BTreeMap, BTreeSet};

use anyhow::{Context, Result, bail};

/// A compiled unit: package, target, kind and mode (library, build script, ...).
type UnitKey = (String, String, String, String);
/// How it is compiled: its features and profile.
type UnitBuild = (Vec<String>, String);

/// Cargo's unit graph of `args` (a `build` or `test` command line), registry crates only.
fn registry_units(args: &[&str]) -> Result<BTreeMap<UnitKey, BTreeSet<UnitBuild>>> {
    let out = crate::cargo()
        .env("RUSTC_BOOTSTRAP", "1")
        .args(args)
        .args(["-Z", "unstable-options", "--unit-graph"])
        .output()
        .context("running cargo")?;
    if !out.status.success() {
        bail!(
            "cargo {} --unit-graph failed:\n{}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let graph: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("cargo {} printed no unit graph", args.join(" ")))?;
    let Some(units) = graph["units"].as_array() else {
        bail!("cargo {}: the unit graph has no `units`", args.join(" "));
    };
    let mut map: BTreeMap<UnitKey, BTreeSet<UnitBuild>> = BTreeMap::new();
    for u in units {
        let pkg = u["pkg_id"].as_str().unwrap_or_default();
        if !pkg.starts_with("registry+") {
            continue;
        }
        let key = (
            pkg.rsplit('#').next().unwrap_or(pkg).to_string(),
            u["target"]["name"].as_str().unwrap_or_default().to_string(),
            u["target"]["kind"].to_string(),
            format!("{} {}", u["mode"], u["platform"]),
        );
        let mut features: Vec<String> = u["features"]
            .as_array()
            .map(|f| {
                f.iter()
                    .filter_map(|x| x.as_str().map(str::to_string))
                    .collect()
            })
            .unwrap_or_default();
        features.sort();
        map.entry(key)
            .or_default()
            .insert((features, u["profile"].to_string()));
    }
    Ok(map)
}

/// The units of `binary` that `other` lacks or compiles with other features or profile.
fn differences(
    binary: &BTreeMap<UnitKey, BTreeSet<UnitBuild>>,
    other: &BTreeMap<UnitKey, BTreeSet<UnitBuild>>,
) -> Vec<String> {
    let mut bad = Vec::new();
    for (key, builds) in binary {
        let Some(theirs) = other.get(key) else {
            bad.push(format!("{} ({}) is not built", key.0, key.1));
            continue;
        };
        for (features, _) in builds.iter().filter(|b| !theirs.contains(b)) {
            let others: Vec<String> = theirs.iter().map(|(f, _)| f.join(",")).collect();
            bad.push(format!(
                "{} ({}): features [{}] here, [{}] there (or another profile)",
                key.0,
                key.1,
                features.join(","),
                others.join("] or [")
            ));
        }
    }
    bad
}

pub fn build_check() -> Result<()> {
    let binary = registry_units(&crate::BUILD_BITT)?;
    let builds = [
        (
            "cargo test --workspace --release",
            vec!["test", "--release", "--workspace", "--no-run"],
        ),
        (
            "cargo build --release --workspace --all-targets",
            vec!["build", "--release", "--workspace", "--all-targets"],
        ),
    ];
    let mut failed = false;
    for (name, args) in builds {
        let other = registry_units(&args)?;
        let bad = differences(&binary, &other);
        if bad.is_empty() {
            println!(
                "build-check: all {} registry units of the bitt binary are compiled the same by `{name}` (no rebuild)",
                binary.len()
            );
        } else {
            failed = true;
            println!(
                "build-check: `{name}` would compile {} registry units of the bitt binary again:",
                bad.len()
            );
            for line in &bad {
                println!("  {line}");
            }
        }
    }
    if failed {
        bail!(
            "the bitt binary and the tests resolve registry crates differently: pin the features in [workspace.dependencies]"
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn units(list: &[(&str, &[&str])]) -> BTreeMap<UnitKey, BTreeSet<UnitBuild>> {
        let mut map: BTreeMap<UnitKey, BTreeSet<UnitBuild>> = BTreeMap::new();
        for (name, features) in list {
            let key = (
                name.to_string(),
                name.to_string(),
                "[\"lib\"]".into(),
                "\"build\" null".into(),
            );
            map.entry(key).or_default().insert((
                features.iter().map(|f| f.to_string()).collect(),
                "{}".into(),
            ));
        }
        map
    }

    #[test]
    fn a_unit_built_with_other_features_or_not_at_all_is_named() {
        let binary = units(&[("burn@0.22.1", &["flex", "std"]), ("half@2.7.1", &["std"])]);
        let same = units(&[
            ("burn@0.22.1", &["flex", "std"]),
            ("half@2.7.1", &["std"]),
            ("proptest@1.0.0", &[]),
        ]);
        assert!(differences(&binary, &same).is_empty());
        let other = units(&[("burn@0.22.1", &["flex", "std", "wgpu"])]);
        let bad = differences(&binary, &other);
        assert_eq!(bad.len(), 2, "{bad:?}");
        assert!(bad[0].starts_with(
            "burn@0.22.1 (burn@0.22.1): features [flex,std] here, [flex,std,wgpu] there"
        ));
        assert_eq!(bad[1], "half@2.7.1 (half@2.7.1) is not built");
    }
}
