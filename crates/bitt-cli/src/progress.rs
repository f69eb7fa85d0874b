//! Progress on stderr: a bar redrawn in place on a terminal, plain lines every 10 % in a log.

use std::io::Write;
use std::time::Instant;

use bitt::fit::{FitObserver, FitProgress};
use bitt::refine::{RefineObserver, RefineProgress};
use bitt::train_scene::SetupObserver;

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
    /// Which lines a log has had.
    log: LogLines,
}

impl ProgressLine {
    /// A line whose last step ends it on a terminal.
    pub(crate) fn new() -> Self {
        use std::io::IsTerminal;
        ProgressLine {
            started: Instant::now(),
            terminal: std::io::stderr().is_terminal(),
            newline_at_end: true,
            log: LogLines::default(),
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
        } else if self.log.due(done, total) {
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

/// The mesh refinement's progress line.
pub(crate) struct RefineBar {
    line: ProgressLine,
}

impl RefineBar {
    pub(crate) fn new() -> Self {
        RefineBar {
            line: ProgressLine::new(),
        }
    }
}

impl RefineObserver for RefineBar {
    fn iteration(&mut self, p: &RefineProgress) {
        let per = self.line.elapsed() / p.iteration.max(1) as f64;
        let text = format!(
            "{:5} loss {:.4} IoU {:.3} {:.2} s/it",
            p.stage, p.terms.total, p.iou, per
        );
        self.line.show("refine ", p.iteration, p.iterations, &text);
    }
}

/// The keypoint fit's progress line (its plan grows with each restart, so the caller ends
/// the line).
pub(crate) struct FitBar {
    line: ProgressLine,
}

impl FitBar {
    pub(crate) fn new() -> Self {
        FitBar {
            line: ProgressLine::open_ended(),
        }
    }
}

impl FitObserver for FitBar {
    fn iteration(&mut self, p: &FitProgress) {
        let text = format!(
            "{:10} loss {:.4} {:.1} s",
            p.stage,
            p.loss,
            self.line.elapsed()
        );
        self.line.show("fit ", p.iteration, p.iterations, &text);
    }
}

/// A run's setup on stderr: its lines, and a bar for each refinement, keypoint fit and
/// texture PCA fit.
pub(crate) struct SetupLines;

impl SetupObserver for SetupLines {
    fn say(&mut self, line: &str) {
        eprintln!("{line}");
    }

    fn refine(&mut self) -> Box<dyn RefineObserver> {
        Box::new(RefineBar::new())
    }

    fn fit(&mut self) -> Box<dyn FitObserver> {
        Box::new(FitBar::new())
    }

    fn pca(&mut self) -> Box<dyn bitt_texture::FitProgress> {
        Box::new(PcaFitBar::new())
    }
}

/// The tenth of the work that `done` of `total` has reached (0 to 10; `total` 0 counts as 1,
/// `done` past `total` as `total`).
fn tenth(done: usize, total: usize) -> usize {
    let total = total.max(1);
    // u128: `10 * done` cannot overflow.
    (10 * done.min(total) as u128 / total as u128) as usize
}

/// Whether a log gets a line at `done` of `total`, given the tenth its last line was at
/// (`None`: no line yet for this total): the first report, then whenever the work reaches a
/// tenth not printed yet (so at most 11 lines, the last at `done == total`). Steps that are
/// skipped or reported twice neither hide a tenth nor repeat one. Returns the tenth to
/// remember.
fn plain_line_due(done: usize, total: usize, last: Option<usize>) -> Option<usize> {
    let now = tenth(done, total);
    match last {
        Some(last) if now <= last => None,
        _ => Some(now),
    }
}

/// The lines a log has had of one progress line: the total and the tenth of the last one. A
/// new total (the keypoint fit's plan grows with each restart) starts a new count.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
struct LogLines {
    last: Option<(usize, usize)>,
}

impl LogLines {
    /// Whether `done` of `total` gets a line; remembers it if so.
    fn due(&mut self, done: usize, total: usize) -> bool {
        let last = self
            .last
            .filter(|&(t, _)| t == total)
            .map(|(_, tenth)| tenth);
        match plain_line_due(done, total, last) {
            Some(tenth) => {
                self.last = Some((total, tenth));
                true
            }
            None => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{LogLines, plain_line_due};

    /// The reports of `steps` that a log prints.
    fn logged(steps: impl IntoIterator<Item = (usize, usize)>) -> Vec<(usize, usize)> {
        let mut log = LogLines::default();
        steps
            .into_iter()
            .filter(|&(done, total)| log.due(done, total))
            .collect()
    }

    #[test]
    fn the_decision_follows_the_last_printed_tenth() {
        // Nothing printed yet: always print, and remember the tenth reached.
        assert_eq!(plain_line_due(1, 200, None), Some(0));
        assert_eq!(plain_line_due(0, 5, None), Some(0));
        assert_eq!(plain_line_due(301, 700, None), Some(4));
        // Within the tenth already printed: nothing.
        assert_eq!(plain_line_due(19, 200, Some(0)), None);
        assert_eq!(plain_line_due(20, 200, Some(1)), None);
        // A new tenth, however many steps were skipped to reach it.
        assert_eq!(plain_line_due(20, 200, Some(0)), Some(1));
        assert_eq!(plain_line_due(95, 200, Some(1)), Some(4));
        // The end is its own tenth; past the end counts as the end; a zero total is one.
        assert_eq!(plain_line_due(200, 200, Some(9)), Some(10));
        assert_eq!(plain_line_due(200, 200, Some(10)), None);
        assert_eq!(plain_line_due(250, 200, Some(9)), Some(10));
        assert_eq!(plain_line_due(1, 0, None), Some(10));
        assert_eq!(plain_line_due(usize::MAX, usize::MAX, Some(9)), Some(10));
    }

    #[test]
    fn a_log_gets_a_line_every_tenth() {
        let done = |lines: Vec<(usize, usize)>| lines.iter().map(|l| l.0).collect::<Vec<_>>();
        // A 200-iteration run: 11 lines instead of 200 redraws.
        let lines = logged((1..=200).map(|i| (i, 200)));
        assert_eq!(
            done(lines),
            vec![1, 20, 40, 60, 80, 100, 120, 140, 160, 180, 200]
        );
        // Fewer steps than tenths: every step.
        assert_eq!(
            done(logged((1..=7).map(|i| (i, 7)))),
            vec![1, 2, 3, 4, 5, 6, 7]
        );
        // A PCA stage reports 0 first; a one-step stage gets its start and its end.
        assert_eq!(done(logged((0..=1).map(|i| (i, 1)))), vec![0, 1]);
        // A resumed run starts with a line, then continues at the next tenth.
        assert_eq!(
            done(logged((301..=700).map(|i| (i, 700)))),
            vec![301, 350, 420, 490, 560, 630, 700]
        );
        // Reports every 7 steps still get one line per tenth, the end included.
        assert_eq!(
            done(logged((7..=100).step_by(7).chain([100]).map(|i| (i, 100)))),
            vec![7, 14, 21, 35, 42, 56, 63, 70, 84, 91, 100]
        );
        // A repeated report is not printed twice.
        assert_eq!(
            logged([(50, 100), (50, 100), (100, 100), (100, 100)]).len(),
            2
        );
        // A total that grows (the keypoint fit's restarts) starts a new count at once.
        let lines = logged(
            (1..=150)
                .map(|i| (i, 150))
                .chain((151..=300).map(|i| (i, 300))),
        );
        assert_eq!(
            lines
                .iter()
                .filter(|l| l.1 == 300)
                .map(|l| l.0)
                .collect::<Vec<_>>(),
            vec![151, 180, 210, 240, 270, 300]
        );
    }
}
