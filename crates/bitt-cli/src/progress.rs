//! Progress on stderr: a bar redrawn in place on a terminal, plain lines every 10 % in a log.

use std::io::Write;
use std::time::Instant;

/// One progress line on stderr. On a terminal the bar is redrawn in place; when stderr is
/// not a terminal (CI logs, `| tee`, Slurm output files) it prints one plain line at the first
/// step, whenever another 10 % is done, and at the end, instead of carriage-return redraws
/// that would make a whole run one long line.
#[derive(Debug)]
pub(crate) struct ProgressLine {
    started: Instant,
    terminal: bool,
    /// End the line on a terminal when the last step is shown.
    newline_at_end: bool,
}

impl ProgressLine {
    /// A line whose last step ends it on a terminal.
    pub(crate) fn new() -> Self {
        use std::io::IsTerminal;
        ProgressLine {
            started: Instant::now(),
            terminal: std::io::stderr().is_terminal(),
            newline_at_end: true,
        }
    }

    /// A line the caller ends (its total may still grow, as the keypoint fit's does).
    pub(crate) fn open_ended() -> Self {
        ProgressLine {
            newline_at_end: false,
            ..Self::new()
        }
    }

    /// Seconds since the line was made.
    pub(crate) fn elapsed(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    /// Shows `label [####------] done/total text`.
    pub(crate) fn show(&mut self, label: &str, done: usize, total: usize, text: &str) {
        let width = 30;
        let filled = (width * done / total.max(1)).min(width);
        let line = format!(
            "{label}[{}{}] {done}/{total} {text}",
            "#".repeat(filled),
            "-".repeat(width - filled)
        );
        if self.terminal {
            eprint!("\r{line}   ");
            if self.newline_at_end && done == total {
                eprintln!();
            }
        } else if plain_line_due(done, total) {
            eprintln!("{line}");
        }
        let _ = std::io::stderr().flush();
    }
}

/// The texture PCA fit's progress (`bitt_texture::FitProgress`): one [`ProgressLine`] per
/// stage (generating identities, Gram matrix, eigendecomposition, ...), labelled with it.
#[derive(Debug)]
pub(crate) struct PcaFitBar {
    current: std::sync::Mutex<Option<(bitt_texture::FitStage, ProgressLine)>>,
}

impl PcaFitBar {
    pub(crate) fn new() -> Self {
        PcaFitBar {
            current: std::sync::Mutex::new(None),
        }
    }
}

impl bitt_texture::FitProgress for PcaFitBar {
    fn report(&self, stage: bitt_texture::FitStage, done: usize, total: usize) {
        let mut current = self.current.lock().unwrap_or_else(|e| e.into_inner());
        if current.as_ref().is_none_or(|(s, _)| *s != stage) {
            *current = Some((stage, ProgressLine::new()));
        }
        if let Some((_, line)) = current.as_mut() {
            let text = format!("{:.0} s", line.elapsed());
            line.show(
                &format!("texture PCA: {} ", stage.label()),
                done,
                total,
                &text,
            );
        }
    }
}

/// Whether a log gets a line at step `done` of `total`: the first, the last, and each step
/// that crosses another tenth.
fn plain_line_due(done: usize, total: usize) -> bool {
    let total = total.max(1);
    done <= 1 || done >= total || 10 * done / total != 10 * (done - 1) / total
}

#[cfg(test)]
mod tests {
    use super::plain_line_due;

    #[test]
    fn a_log_gets_a_line_every_tenth() {
        let due: Vec<usize> = (1..=200).filter(|&i| plain_line_due(i, 200)).collect();
        assert_eq!(due, vec![1, 20, 40, 60, 80, 100, 120, 140, 160, 180, 200]);
        let due: Vec<usize> = (1..=7).filter(|&i| plain_line_due(i, 7)).collect();
        assert_eq!(due, vec![1, 2, 3, 4, 5, 6, 7]);
        assert!(plain_line_due(1, 0));
    }
}
