//! Progress on stderr: a bar redrawn in place on a terminal, plain lines every 10 % in a log.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use bitt::fit::{FitObserver, FitProgress};
use bitt::refine::{RefineObserver, RefineProgress};
use bitt::train_scene::SetupObserver;
use bitt::{Observer, Progress};
use bitt_bench::benchmark::EvalObserver;

/// One progress line on stderr. On a terminal the bar is redrawn in place; when stderr is
/// not a terminal (CI logs, `| tee`, Slurm output files) it prints one plain line at the first
/// step, whenever another 10 % is done, and at the end, instead of carriage-return redraws
/// that would make a whole run one long line.
#[derive(Debug)]
pub struct ProgressLine {
    started: Instant,
    terminal: bool,
    /// End the line on a terminal when the last step is shown.
    newline_at_end: bool,
    /// Which lines a log has had.
    log: LogLines,
}

impl ProgressLine {
    /// A line whose last step ends it on a terminal.
    pub fn new() -> Self {
        use std::io::IsTerminal;
        ProgressLine {
            started: Instant::now(),
            terminal: std::io::stderr().is_terminal(),
            newline_at_end: true,
            log: LogLines::default(),
        }
    }

    /// A line the caller ends (its total may still grow, as the keypoint fit's does).
    pub fn open_ended() -> Self {
        ProgressLine {
            newline_at_end: false,
            ..Self::new()
        }
    }

    /// Seconds since the line was made.
    pub fn elapsed(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    /// Shows `label [####------] done/total text`.
    pub fn show(&mut self, label: &str, done: usize, total: usize, text: &str) {
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
#[derive(Debug, Default)]
pub struct PcaFitBar {
    current: std::sync::Mutex<Option<(bitt_texture::FitStage, ProgressLine)>>,
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
#[derive(Debug, Default)]
pub struct RefineBar {
    line: ProgressLine,
    rate: StepRate,
}

impl RefineObserver for RefineBar {
    fn iteration(&mut self, p: &RefineProgress) {
        let per = self.rate.step();
        let text = format!(
            "{:5} loss {:.4} IoU {:.3} {}",
            p.stage,
            p.terms.total,
            p.iou,
            StepRate::text(per, p.iterations.saturating_sub(p.iteration))
        );
        self.line.show("refine ", p.iteration, p.iterations, &text);
    }
}

/// The keypoint fit's progress line (its plan grows with each restart, so the caller ends
/// the line).
#[derive(Debug)]
pub struct FitBar {
    line: ProgressLine,
}

impl Default for FitBar {
    fn default() -> Self {
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
#[derive(Debug)]
pub struct SetupLines;

impl SetupObserver for SetupLines {
    fn say(&mut self, line: &str) {
        eprintln!("{line}");
    }

    fn refine(&mut self) -> Box<dyn RefineObserver> {
        Box::<RefineBar>::default()
    }

    fn fit(&mut self) -> Box<dyn FitObserver> {
        Box::<FitBar>::default()
    }

    fn pca(&mut self) -> Box<dyn bitt_texture::FitProgress> {
        Box::<PcaFitBar>::default()
    }
}

/// Seconds per step for an ETA: a moving average of the measured steps. The first step is
/// left out (it pays for allocations and first-use set-up: 1.7 s where the steps after it
/// take 0.6, which made the first ETA of a 700-step run 3x too long), and the average weighs
/// the last ~20 steps most, so it follows a run whose steps speed up or slow down.
#[derive(Debug, Clone, Default)]
pub struct StepRate {
    /// When the last step was reported.
    last: Option<Instant>,
    /// The moving average (seconds per step), once a step was measured.
    mean: Option<f64>,
}

impl StepRate {
    /// Weight of the newest step in the moving average (about the last 20 steps count).
    const WEIGHT: f64 = 0.1;

    /// A step ended now; the seconds per step so far (`None` until a step after the first
    /// one was measured).
    pub fn step(&mut self) -> Option<f64> {
        let now = Instant::now();
        let seconds = self.last.map(|last| (now - last).as_secs_f64());
        self.last = Some(now);
        seconds.map(|s| self.measured(s))
    }

    /// Adds one measured step of `seconds`; returns the new average.
    fn measured(&mut self, seconds: f64) -> f64 {
        let mean = match self.mean {
            Some(m) => m + Self::WEIGHT * (seconds - m),
            None => seconds,
        };
        self.mean = Some(mean);
        mean
    }

    /// `s/it ETA` text for `remaining` steps.
    fn text(per: Option<f64>, remaining: usize) -> String {
        match per {
            Some(per) => format!("{per:.2} s/it ETA {:.0} s", per * remaining as f64),
            None => "ETA --".to_string(),
        }
    }
}

/// The training progress line; a caller's flag (Ctrl-C) stops the training.
#[derive(Debug)]
pub struct TrainBar {
    line: ProgressLine,
    rate: StepRate,
    stop: Arc<AtomicBool>,
}

impl TrainBar {
    /// A line for a training; `stop` set makes the trainer save and stop.
    pub fn new(stop: Arc<AtomicBool>) -> Self {
        TrainBar {
            line: ProgressLine::new(),
            rate: StepRate::default(),
            stop,
        }
    }
}

impl Observer for TrainBar {
    fn iteration(&mut self, p: &Progress) {
        let per = self.rate.step();
        self.line.show(
            "",
            p.iteration,
            p.iterations,
            &format!(
                "loss {:.4} PSNR {:.2} dB lr {:.1e} {}",
                p.terms.total,
                p.psnr,
                p.learning_rate,
                StepRate::text(per, p.iterations.saturating_sub(p.iteration))
            ),
        );
    }

    fn recovered(&mut self, iteration: usize, message: &str) {
        eprintln!("\nwarning: at iteration {iteration}: {message}");
    }

    fn should_stop(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }
}

/// Progress over a whole evaluation: BiTT iterations are the unit of work.
#[derive(Debug)]
pub struct EvalBar {
    line: ProgressLine,
    /// When the first iteration ended (the ETA leaves the first one out, as [`StepRate`]).
    first: Option<Instant>,
    done: usize,
    total: usize,
    label: String,
}

impl Default for EvalBar {
    /// A line whose total the evaluation's plan sets.
    fn default() -> Self {
        EvalBar {
            line: ProgressLine::open_ended(),
            first: None,
            done: 0,
            total: 0,
            label: String::new(),
        }
    }
}

impl Observer for EvalBar {
    fn iteration(&mut self, p: &Progress) {
        self.done += 1;
        // The mean since the first iteration (not a moving average: the set-up of every
        // further scene, its texture prior and renders, is part of what remains).
        let first = *self.first.get_or_insert_with(Instant::now);
        let measured = self.done - 1;
        let remaining = self.total.saturating_sub(self.done) as f64;
        let eta =
            (measured > 0).then(|| first.elapsed().as_secs_f64() / measured as f64 * remaining);
        let label = format!(
            "{} it {}/{} loss {:.4} | eval ",
            self.label, p.iteration, p.iterations, p.terms.total
        );
        let text = eta.map_or("ETA --".to_string(), |eta| {
            format!("ETA {:.0} min", eta / 60.0)
        });
        self.line.show(&label, self.done, self.total, &text);
    }
    fn recovered(&mut self, iteration: usize, message: &str) {
        eprintln!("\nrecovered at iteration {iteration}: {message}");
    }
}

impl EvalObserver for EvalBar {
    fn say(&mut self, line: &str) {
        eprintln!("{line}");
    }

    fn plan(&mut self, iterations: usize) {
        self.total = iterations;
    }

    fn scene(&mut self, label: String) {
        self.label = label;
    }

    fn pca(&mut self) -> Box<dyn bitt_texture::FitProgress> {
        Box::<PcaFitBar>::default()
    }
}

impl Default for ProgressLine {
    fn default() -> Self {
        Self::new()
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
    use super::{LogLines, StepRate, plain_line_due};

    /// The first step (set-up) is not measured; a slow start does not inflate the estimate,
    /// and the average follows a change of speed within a few tens of steps.
    #[test]
    fn the_step_rate_leaves_out_the_first_step_and_follows_changes() {
        let mut rate = StepRate::default();
        assert_eq!(rate.step(), None);
        assert_eq!(StepRate::text(None, 10), "ETA --");
        let mut rate = StepRate::default();
        assert_eq!(rate.measured(0.6), 0.6);
        for _ in 0..5 {
            rate.measured(0.6);
        }
        assert!((rate.mean.unwrap() - 0.6).abs() < 1e-12);
        // Steps that slow to 1.0 s: within 30 steps the estimate is within 5 % of them.
        let mut after = 0.0;
        for _ in 0..30 {
            after = rate.measured(1.0);
        }
        assert!((after - 1.0).abs() < 0.05, "{after}");
        assert_eq!(StepRate::text(Some(0.5), 100), "0.50 s/it ETA 50 s");
    }

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
