//! Writes every fuzz target's seed files into `fuzz/corpus/<target>/`
//! (`bitt_tests::fuzz_seeds`). `cargo xtask fuzz-seeds` runs it.

fn main() -> std::io::Result<()> {
    let n = bitt_tests::fuzz_seeds::write_seeds()?;
    println!(
        "wrote {n} seed files below {}",
        bitt_tests::fuzz_seeds::corpus_dir("").display()
    );
    Ok(())
}
