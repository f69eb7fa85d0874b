//! The loss plot of a run (`loss.png`): every loss term and the weighted total per iteration
//! on a log axis with decade ticks, the learning-rate steps as dashed vertical lines, axis
//! titles and a legend.
//!
//! `plotters` draws the chart (axes, grid, tick marks, curves) on its bitmap backend and none
//! of the text; the text is rasterized afterwards by `ab_glyph` (sub-pixel glyph positions,
//! kerning, antialiasing) from a font embedded in the binary
//! (`assets/fonts/DejaVuSans-subset.ttf`, licence next to it), so the picture is the same on
//! every machine and nothing looks up system fonts.
//!
//! Values that cannot go on a log axis (NaN, infinite, zero, negative, or outside
//! [`DRAWN_RANGE`], which no loss reaches) are skipped: the curve breaks there. A term with
//! no such value at all (`alb` when its weight is 0) is listed in the legend, greyed, as not
//! drawn. An empty history (or one without any drawable value) is not an error: it still
//! gives a plot, with axes, the legend and a note saying there is nothing to draw ("no
//! iterations"), so a run folder is always complete and its report always has the picture.

use std::path::Path;

use crate::export::png_bytes;
use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use bitt_stdx::write_atomically;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use crate::OutputError;
use bitt_train::config::OptimConfig;
use bitt_train::losses::LossTerms;

/// The plot's size in pixels. At most 768 wide: the report shows images at up to 48em
/// (768 px) with nearest-neighbour scaling, which would break the text of a wider one.
pub(crate) const PLOT_SIZE: (u32, u32) = (760, 480);

/// Height of the legend under the chart: [`LEGEND_COLUMNS`] entries a row, rows of
/// [`LEGEND_ROW`] pixels.
const LEGEND_HEIGHT: u32 = 84;
const LEGEND_COLUMNS: usize = 3;
const LEGEND_ROW: i32 = 24;
const LEGEND_COLUMN: i32 = 232;

/// Space for the y tick labels and axis title, left of the plotting area.
const Y_LABEL_AREA: u32 = 72;

/// Space for the x tick labels and axis title, below the plotting area.
const X_LABEL_AREA: u32 = 50;

/// Space for the caption above the plotting area.
const CAPTION_AREA: u32 = 40;

/// DejaVu Sans cut down to the characters a plot needs (see `assets/fonts/README.md`).
static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans-subset.ttf");

/// The total's colour and each term's, in [`LossTerms::NAMES`] order.
const TOTAL_COLOR: RGBColor = RGBColor(0, 0, 0);
const TERM_COLORS: [RGBColor; LossTerms::COUNT] = [
    RGBColor(220, 50, 47),
    RGBColor(38, 139, 210),
    RGBColor(133, 153, 0),
    RGBColor(211, 54, 130),
    RGBColor(181, 137, 0),
    RGBColor(42, 161, 152),
];
const STEP_COLOR: RGBColor = RGBColor(110, 110, 110);
const TEXT_COLOR: RGBColor = RGBColor(20, 20, 20);
const NOTE_COLOR: RGBColor = RGBColor(120, 120, 120);

/// Horizontal placement of a label relative to its point.
#[derive(Debug, Clone, Copy, PartialEq)]
enum HAlign {
    Left,
    Centre,
    Right,
}

/// Vertical placement: the top of the capitals at the point, or the point half-way up them.
#[derive(Debug, Clone, Copy, PartialEq)]
enum VAlign {
    Top,
    Middle,
}

/// One piece of text to draw once the chart is done.
#[derive(Debug, Clone)]
struct Label {
    text: String,
    /// `ab_glyph` pixel scale (the font's ascent-to-descent height in pixels).
    size: f32,
    at: (f32, f32),
    align: (HAlign, VAlign),
    color: RGBColor,
    /// Rotated a quarter turn anticlockwise (reads bottom to top), for the y axis title.
    vertical: bool,
}

impl Label {
    fn new(text: impl Into<String>, size: f32, at: (i32, i32), align: (HAlign, VAlign)) -> Self {
        Label {
            text: text.into(),
            size,
            at: (at.0 as f32, at.1 as f32),
            align,
            color: TEXT_COLOR,
            vertical: false,
        }
    }

    fn color(self, color: RGBColor) -> Self {
        Label { color, ..self }
    }
}

/// The embedded font.
fn font() -> Result<FontRef<'static>, OutputError> {
    FontRef::try_from_slice(FONT)
        .map_err(|e| OutputError::Invalid(format!("the embedded plot font cannot be read: {e}")))
}

/// The glyphs of `text` at pixel scale `size` with their x offsets (advances and kerning),
/// and the text's width.
fn layout(font: &FontRef<'_>, text: &str, size: f32) -> (Vec<(ab_glyph::GlyphId, f32)>, f32) {
    let scaled = font.as_scaled(PxScale::from(size));
    let mut width = 0.0f32;
    let mut prev = None;
    let mut glyphs = Vec::new();
    for c in text.chars() {
        let id = scaled.glyph_id(c);
        if let Some(p) = prev {
            width += scaled.kern(p, id);
        }
        glyphs.push((id, width));
        width += scaled.h_advance(id);
        prev = Some(id);
    }
    (glyphs, width)
}

/// Draws `label` onto `img`: glyphs at sub-pixel positions with the font's kerning, coverage
/// blended over what is there; pixels outside the image are dropped.
fn draw_label(img: &mut image::RgbImage, font: &FontRef<'_>, label: &Label) {
    let scaled = font.as_scaled(PxScale::from(label.size));
    // Cap height from the outline of `H`, for vertical placement.
    let cap = scaled
        .outline_glyph(scaled.scaled_glyph('H'))
        .map_or(0.7 * label.size, |g| -g.px_bounds().min.y);
    let (glyphs, width) = layout(font, &label.text, label.size);
    // The text's own frame: x along the text, y down, anchor at the origin.
    let x0 = match label.align.0 {
        HAlign::Left => 0.0,
        HAlign::Centre => -width / 2.0,
        HAlign::Right => -width,
    };
    let baseline = match label.align.1 {
        VAlign::Top => cap,
        VAlign::Middle => cap / 2.0,
    };
    let (ax, ay) = label.at;
    // Horizontal text is laid out at its exact (fractional) place; vertical text in its own
    // frame, then turned onto whole pixels.
    let origin = if label.vertical { (0.0, 0.0) } else { (ax, ay) };
    let (w, h) = (img.width() as i64, img.height() as i64);
    let [r, g, b] = [label.color.0, label.color.1, label.color.2].map(f32::from);
    for (id, x) in glyphs {
        let glyph =
            id.with_scale_and_position(label.size, point(origin.0 + x0 + x, origin.1 + baseline));
        let Some(outline) = scaled.outline_glyph(glyph) else {
            continue;
        };
        let bounds = outline.px_bounds();
        outline.draw(|gx, gy, coverage| {
            let (lx, ly) = (
                bounds.min.x as i64 + i64::from(gx),
                bounds.min.y as i64 + i64::from(gy),
            );
            let (px, py) = if label.vertical {
                (ax.round() as i64 + ly, ay.round() as i64 - lx)
            } else {
                (lx, ly)
            };
            if px < 0 || py < 0 || px >= w || py >= h {
                return;
            }
            let a = coverage.clamp(0.0, 1.0);
            let pixel = img.get_pixel_mut(px as u32, py as u32);
            for (c, target) in pixel.0.iter_mut().zip([r, g, b]) {
                *c = (f32::from(*c) * (1.0 - a) + target * a).round() as u8;
            }
        });
    }
}

/// The width in pixels of `text` at pixel scale `size` in the embedded font.
///
/// # Errors
/// Only if the embedded font cannot be read.
pub fn text_width(text: &str, size: f32) -> Result<f32, OutputError> {
    Ok(layout(&font()?, text, size).1)
}

/// Draws `text` onto `img` in the embedded font (as the plot's labels: sub-pixel glyph
/// positions, kerning, antialiased coverage blended over what is there), left-aligned with
/// the top of its capitals at `at`, at pixel scale `size`, in `color`; pixels outside the
/// image are dropped. Other pictures than the plot (the hand detection's overlay) label
/// themselves with it.
///
/// # Errors
/// Only if the embedded font cannot be read.
pub fn draw_text(
    img: &mut image::RgbImage,
    text: &str,
    size: f32,
    at: (f32, f32),
    color: [u8; 3],
) -> Result<(), OutputError> {
    let label = Label {
        text: text.to_string(),
        size,
        at,
        align: (HAlign::Left, VAlign::Top),
        color: RGBColor(color[0], color[1], color[2]),
        vertical: false,
    };
    draw_label(img, &font()?, &label);
    Ok(())
}

/// Writes the loss plot of `history` (one entry per iteration, the first at iteration 1) to
/// `path` as a PNG, atomically; `schedule` gives the learning-rate steps to mark.
///
/// # Errors
/// Writing the file, or drawing (which does not fail on any history: non-finite and
/// non-positive values are skipped, an empty history gives a plot with a note).
pub fn write_loss_plot(
    path: &Path,
    history: &[LossTerms],
    schedule: &OptimConfig,
) -> Result<(), OutputError> {
    let img = loss_plot_image(history, schedule)?;
    write_atomically(path, &png_bytes(&img)?)?;
    Ok(())
}

/// The iterations after which the scheduled learning rate drops (the rate of iteration `i`,
/// counted from 0, is lower than that of `i - 1`): with the paper's schedule (halved every
/// 200) and 700 iterations, `[200, 400, 600]`. Steps stop at the rate's floor.
pub(crate) fn learning_rate_steps(schedule: &OptimConfig, iterations: usize) -> Vec<usize> {
    if schedule.decay_step == 0 {
        return Vec::new();
    }
    (schedule.decay_step..iterations)
        .step_by(schedule.decay_step)
        .filter(|&i| schedule.learning_rate_at(i) < schedule.learning_rate_at(i - 1))
        .collect()
}

/// The decade range `[10^a, 10^b]` (`a < b`) that holds every value in `[lo, hi]`
/// (`0 < lo <= hi`, finite).
fn decade_range(lo: f64, hi: f64) -> (i32, i32) {
    let a = lo.log10().floor() as i32;
    let mut b = hi.log10().ceil() as i32;
    // Rounding of log10 at exact powers of ten.
    if 10f64.powi(b) < hi {
        b += 1;
    }
    let a = if 10f64.powi(a) > lo { a - 1 } else { a };
    (a, b.max(a + 1))
}

/// Iteration ticks for an axis `0..=n`: multiples of 1, 2 or 5 x 10^k, at most 8 of them
/// past 0 (plotters' own integer ticks overflow in debug builds).
fn iteration_ticks(n: usize) -> Vec<usize> {
    let n = n.max(1);
    let mut scale = 1usize;
    loop {
        for m in [1, 2, 5] {
            let step = scale.saturating_mul(m);
            if n / step <= 8 {
                return (0..=n / step).map(|k| k * step).collect();
            }
        }
        scale = scale.saturating_mul(10);
    }
}

/// `n` in Unicode superscript digits (`-3` -> `⁻³`).
fn superscript(n: i32) -> String {
    n.to_string()
        .chars()
        .map(|c| match c {
            '-' => '⁻',
            '0' => '⁰',
            '1' => '¹',
            '2' => '²',
            '3' => '³',
            d => char::from_u32(0x2070 + d.to_digit(10).unwrap_or(0)).unwrap_or(d),
        })
        .collect()
}

/// A decade tick label: `10⁻³`.
fn decade_label(exponent: i32) -> String {
    format!("10{}", superscript(exponent))
}

/// A positive value in scientific notation with at most three significant digits:
/// `1e-3` -> `10⁻³`, `2.5e-4` -> `2.5·10⁻⁴`.
fn scientific(v: f64) -> String {
    if !(v.is_finite() && v > 0.0) {
        return format!("{v}");
    }
    let mut e = v.log10().floor() as i32;
    let mut m = v / 10f64.powi(e);
    // Three significant digits; 9.999 rounds to 10.
    m = (m * 100.0).round() / 100.0;
    if m >= 10.0 {
        m /= 10.0;
        e += 1;
    }
    if (m - 1.0).abs() < 1e-9 {
        decade_label(e)
    } else {
        let text = format!("{m:.2}");
        let text = text.trim_end_matches('0').trim_end_matches('.');
        format!("{text}·{}", decade_label(e))
    }
}

/// The values a curve draws; others are skipped (the axis range is whole decades around
/// the values drawn, and must stay finite and positive).
pub(crate) const DRAWN_RANGE: std::ops::RangeInclusive<f64> = 1e-300..=1e300;

/// One curve: its legend label, colour, width, and its drawable runs of `(iteration, value)`
/// (a value outside [`DRAWN_RANGE`], NaN included, ends a run).
struct Curve {
    label: String,
    color: RGBColor,
    width: u32,
    runs: Vec<Vec<(usize, f64)>>,
}

fn curve(label: &str, color: RGBColor, width: u32, values: impl Iterator<Item = f64>) -> Curve {
    let mut runs: Vec<Vec<(usize, f64)>> = Vec::new();
    let mut open = false;
    for (k, v) in values.enumerate() {
        if DRAWN_RANGE.contains(&v) {
            if !open {
                runs.push(Vec::new());
                open = true;
            }
            if let Some(run) = runs.last_mut() {
                run.push((k + 1, v));
            }
        } else {
            open = false;
        }
    }
    Curve {
        label: label.to_string(),
        color,
        width,
        runs,
    }
}

/// The curves: the weighted total first, then each term in [`LossTerms::NAMES`] order.
fn curves(history: &[LossTerms]) -> Vec<Curve> {
    let mut out = vec![curve(
        "total (weighted)",
        TOTAL_COLOR,
        3,
        history.iter().map(|t| t.total),
    )];
    for (i, (name, color)) in LossTerms::NAMES.iter().zip(TERM_COLORS).enumerate() {
        out.push(curve(name, color, 2, history.iter().map(|t| t.values()[i])));
    }
    out
}

/// A plotters drawing error as the crate's error.
fn draw_error(e: impl std::fmt::Display) -> OutputError {
    OutputError::Invalid(format!("drawing the loss plot: {e}"))
}

/// The loss plot of `history` as an image of [`PLOT_SIZE`] (see [`write_loss_plot`]).
///
/// # Errors
/// Only if the embedded font cannot be read or plotters fails to draw.
pub(crate) fn loss_plot_image(
    history: &[LossTerms],
    schedule: &OptimConfig,
) -> Result<image::RgbImage, OutputError> {
    let font = font()?;
    let (w, h) = PLOT_SIZE;
    let mut buffer = vec![255u8; 3 * w as usize * h as usize];
    let labels = draw_chart(&mut buffer, &font, history, schedule).map_err(draw_error)?;
    let mut img = image::RgbImage::from_raw(w, h, buffer)
        .ok_or_else(|| OutputError::Invalid("loss plot buffer has the wrong size".into()))?;
    for label in &labels {
        draw_label(&mut img, &font, label);
    }
    Ok(img)
}

/// Draws everything but the text into `buffer` (RGB, [`PLOT_SIZE`]) and returns the text to
/// draw, placed with the chart's coordinates.
fn draw_chart(
    buffer: &mut [u8],
    font: &FontRef<'_>,
    history: &[LossTerms],
    schedule: &OptimConfig,
) -> Result<Vec<Label>, Box<dyn std::error::Error>> {
    let (w, h) = PLOT_SIZE;
    let root = BitMapBackend::with_buffer(buffer, (w, h)).into_drawing_area();
    root.fill(&WHITE)?;
    let (plot_area, legend_area) = root.split_vertically(h - LEGEND_HEIGHT);
    let mut labels = Vec::new();

    let curves = curves(history);
    let (lo, hi) = curves
        .iter()
        .flat_map(|c| c.runs.iter().flatten())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &(_, v)| {
            (lo.min(v), hi.max(v))
        });
    let drawable = lo.is_finite() && hi.is_finite();
    let (a, b) = if drawable {
        decade_range(lo, hi)
    } else {
        (-3, 0)
    };
    // At most ~8 labelled decades; minor ticks (2..9 x 10^k) when there are few.
    let every = ((b - a) as usize).div_ceil(8).max(1);
    let decades: Vec<i32> = (a..=b)
        .filter(|e| ((e - a) as usize).is_multiple_of(every))
        .collect();
    let minor: Vec<f64> = if b - a <= 6 {
        (a..b)
            .flat_map(|e| (2..10).map(move |m| f64::from(m) * 10f64.powi(e)))
            .collect()
    } else {
        Vec::new()
    };
    let n = history.len().max(1);
    let x_ticks = iteration_ticks(n);
    let (ylo, yhi) = (10f64.powi(a), 10f64.powi(b));

    let mut chart = ChartBuilder::on(&plot_area)
        .margin_top(CAPTION_AREA)
        .margin_right(22)
        .margin_bottom(0)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(
            (0usize..n).with_key_points(x_ticks.clone()),
            (ylo..yhi)
                .log_scale()
                .with_key_points(decades.iter().map(|&e| 10f64.powi(e)).collect())
                .with_light_points(minor),
        )?;
    // Tick marks and grid from plotters, tick labels from `draw_label`: plotters' own are
    // empty and transparent (the backend skips transparent text, so plotters' font code,
    // which cannot draw without a font feature, is never asked to).
    let no_label_x = |_: &usize| String::new();
    let no_label_y = |_: &f64| String::new();
    chart
        .configure_mesh()
        .x_label_formatter(&no_label_x)
        .y_label_formatter(&no_label_y)
        .label_style(("sans-serif", 1).into_font().color(&TRANSPARENT))
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(238, 238, 238))
        .axis_style(TEXT_COLOR)
        .set_all_tick_mark_size(5)
        .draw()?;
    let (px, py) = chart.plotting_area().get_pixel_range();
    let centre_x = (px.start + px.end) / 2;
    labels.push(Label::new(
        "loss per iteration (log scale)",
        22.0,
        (centre_x, 14),
        (HAlign::Centre, VAlign::Top),
    ));
    for &t in &x_ticks {
        let (x, _) = chart.backend_coord(&(t, ylo));
        labels.push(Label::new(
            t.to_string(),
            16.0,
            (x, py.end + 10),
            (HAlign::Centre, VAlign::Top),
        ));
    }
    for &e in &decades {
        let (_, y) = chart.backend_coord(&(0, 10f64.powi(e)));
        labels.push(Label::new(
            decade_label(e),
            16.0,
            (px.start - 9, y),
            (HAlign::Right, VAlign::Middle),
        ));
    }
    labels.push(Label::new(
        "iteration",
        17.0,
        (centre_x, py.end + 32),
        (HAlign::Centre, VAlign::Top),
    ));
    labels.push(Label {
        vertical: true,
        ..Label::new(
            "loss",
            17.0,
            (14, (py.start + py.end) / 2),
            (HAlign::Centre, VAlign::Top),
        )
    });

    // Learning-rate steps: dashed vertical lines, each segment's rate at its top left when
    // the segment is wide enough to hold it.
    let steps = learning_rate_steps(schedule, history.len());
    for &s in &steps {
        chart.draw_series(DashedLineSeries::new(
            [(s, ylo), (s, yhi)],
            6,
            5,
            STEP_COLOR.stroke_width(1),
        ))?;
    }
    if !history.is_empty() {
        let starts: Vec<usize> = std::iter::once(0).chain(steps.iter().copied()).collect();
        let ends = starts.iter().skip(1).copied().chain([history.len()]);
        for (&s, e) in starts.iter().zip(ends) {
            let (x, y) = chart.backend_coord(&(s, yhi));
            let room = chart.backend_coord(&(e, yhi)).0 - x;
            let text = format!("lr {}", scientific(schedule.learning_rate_at(s)));
            if layout(font, &text, 14.0).1 + 10.0 <= room as f32 {
                labels.push(
                    Label::new(text, 14.0, (x + 5, y + 6), (HAlign::Left, VAlign::Top))
                        .color(STEP_COLOR),
                );
            }
        }
    }

    // The total last, on top of the terms.
    for c in curves.iter().skip(1).chain(curves.iter().take(1)) {
        for run in &c.runs {
            if run.len() == 1 {
                chart.draw_series(std::iter::once(Circle::new(
                    run[0],
                    c.width + 1,
                    c.color.filled(),
                )))?;
            } else {
                chart.draw_series(LineSeries::new(
                    run.iter().copied(),
                    c.color.stroke_width(c.width),
                ))?;
            }
        }
    }

    if !drawable {
        let text = if history.is_empty() {
            "no iterations"
        } else {
            "no loss values to draw"
        };
        labels.push(
            Label::new(
                text,
                24.0,
                (centre_x, (py.start + py.end) / 2),
                (HAlign::Centre, VAlign::Middle),
            )
            .color(NOTE_COLOR),
        );
    }

    labels.extend(draw_legend(
        &legend_area,
        &curves,
        schedule,
        !steps.is_empty(),
    )?);
    root.present()?;
    Ok(labels)
}

/// The top left of legend entry `i` in the picture: [`LEGEND_COLUMNS`] a row, under the
/// chart.
fn legend_slot(i: usize) -> (i32, i32) {
    let (w, h) = PLOT_SIZE;
    let width = LEGEND_COLUMNS as i32 * LEGEND_COLUMN;
    let left = (w as i32 - width) / 2 + 10;
    let top = (h - LEGEND_HEIGHT) as i32 + 6;
    (
        left + (i % LEGEND_COLUMNS) as i32 * LEGEND_COLUMN,
        top + (i / LEGEND_COLUMNS) as i32 * LEGEND_ROW,
    )
}

/// Where an entry's name starts, right of its line sample.
const LEGEND_TEXT: i32 = 44;

/// The legend under the chart: one entry per curve (a line sample and its name), then the
/// learning-rate steps. Returns its text, in picture coordinates.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    curves: &[Curve],
    schedule: &OptimConfig,
    has_steps: bool,
) -> Result<Vec<Label>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let top = (PLOT_SIZE.1 - LEGEND_HEIGHT) as i32;
    let mut labels = Vec::new();
    // Picture coordinates to the legend area's.
    let local = |(x, y): (i32, i32)| (x, y - top);
    // A curve without values is greyed and, when others have some, marked as not drawn (with
    // none at all, the note in the chart says so).
    let any_drawn = curves.iter().any(|c| !c.runs.is_empty());
    for (i, c) in curves.iter().enumerate() {
        let (x, y) = legend_slot(i);
        let mid = y + LEGEND_ROW / 2;
        area.draw(&PathElement::new(
            vec![local((x, mid)), local((x + 34, mid))],
            c.color.stroke_width(c.width),
        ))?;
        let at = (x + LEGEND_TEXT, mid);
        labels.push(if c.runs.is_empty() {
            let text = if any_drawn {
                format!("{} (not drawn)", c.label)
            } else {
                c.label.clone()
            };
            Label::new(text, 16.0, at, (HAlign::Left, VAlign::Middle)).color(NOTE_COLOR)
        } else {
            Label::new(c.label.clone(), 16.0, at, (HAlign::Left, VAlign::Middle))
        });
    }
    if has_steps {
        let (x, y) = legend_slot(curves.len());
        let mid = y + LEGEND_ROW / 2;
        area.draw(&DashedPathElement::new(
            vec![local((x, mid)), local((x + 34, mid))],
            6,
            5,
            STEP_COLOR.stroke_width(1),
        ))?;
        let gamma = schedule.decay_gamma;
        let text = if (gamma - 0.5).abs() < 1e-12 {
            "learning rate halved".to_string()
        } else {
            format!("learning rate × {gamma}")
        };
        labels.push(Label::new(
            text,
            16.0,
            (x + LEGEND_TEXT, mid),
            (HAlign::Left, VAlign::Middle),
        ));
    }
    Ok(labels)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Terms that are fixed fractions of `total` (one of them 0, as `alb` is when disabled),
    /// for any number of terms: terms beyond the first six get small fractions of their own,
    /// so no curve hides another.
    fn terms(total: f64) -> LossTerms {
        let fractions = [0.4, 0.5, 0.6, 0.1, 0.0, 0.02];
        let values: Vec<f64> = (0..LossTerms::COUNT)
            .map(|k| fractions.get(k).copied().unwrap_or(0.03 / k as f64) * total)
            .collect();
        LossTerms::from_values(&values, total)
    }

    /// A history shaped like a real run: a fast drop, then slower, with small steps down
    /// where the rate halves.
    fn history(n: usize) -> Vec<LossTerms> {
        (0..n)
            .map(|i| {
                let t = i as f64;
                terms(0.05 + 0.5 * (-t / 40.0).exp() + 0.01 * (t * 0.7).sin().abs())
            })
            .collect()
    }

    /// Pixels darker than a grey level in a rectangle `[x0, x1) x [y0, y1)`.
    fn dark(img: &image::RgbImage, x: (u32, u32), y: (u32, u32), level: u8) -> usize {
        let mut count = 0;
        for yy in y.0..y.1 {
            for xx in x.0..x.1 {
                if img.get_pixel(xx, yy).0.iter().all(|&c| c < level) {
                    count += 1;
                }
            }
        }
        count
    }

    #[test]
    fn learning_rate_steps_follow_the_schedule() {
        let o = OptimConfig::default();
        assert_eq!(learning_rate_steps(&o, 700), vec![200, 400, 600]);
        assert_eq!(learning_rate_steps(&o, 600), vec![200, 400]);
        assert!(learning_rate_steps(&o, 0).is_empty());
        let none = OptimConfig {
            decay_step: 0,
            ..o.clone()
        };
        assert!(learning_rate_steps(&none, 700).is_empty());
        // 1e-3 halved every 10 reaches the 1e-5 floor after 7 halvings: no steps after it.
        let fast = OptimConfig {
            decay_step: 10,
            ..o.clone()
        };
        assert_eq!(
            learning_rate_steps(&fast, 1000),
            vec![10, 20, 30, 40, 50, 60, 70]
        );
        let flat = OptimConfig {
            decay_gamma: 1.0,
            ..o
        };
        assert!(learning_rate_steps(&flat, 700).is_empty());
    }

    #[test]
    fn iteration_ticks_are_round_numbers() {
        assert_eq!(iteration_ticks(0), vec![0, 1]);
        assert_eq!(iteration_ticks(3), vec![0, 1, 2, 3]);
        assert_eq!(iteration_ticks(10), vec![0, 2, 4, 6, 8, 10]);
        assert_eq!(
            iteration_ticks(700),
            vec![0, 100, 200, 300, 400, 500, 600, 700]
        );
        assert_eq!(iteration_ticks(2000), vec![0, 500, 1000, 1500, 2000]);
        assert!(iteration_ticks(usize::MAX).len() <= 9);
    }

    #[test]
    fn labels_use_superscript_decades() {
        assert_eq!(decade_label(-3), "10⁻³");
        assert_eq!(decade_label(0), "10⁰");
        assert_eq!(decade_label(12), "10¹²");
        assert_eq!(scientific(1e-3), "10⁻³");
        assert_eq!(scientific(5e-4), "5·10⁻⁴");
        assert_eq!(scientific(1.25e-4), "1.25·10⁻⁴");
        assert_eq!(scientific(9.999e-2), "10⁻¹");
        assert_eq!(decade_range(0.02, 0.6), (-2, 0));
        assert_eq!(decade_range(0.1, 1.0), (-1, 0));
        assert_eq!(decade_range(0.5, 0.5), (-1, 0));
        assert_eq!(decade_range(1e-3, 1e-3), (-3, -2));
        // Every character the plot writes is in the embedded font.
        let font = font().unwrap();
        let written = format!(
            "{}{}{} loss per iteration (log scale) iteration total (weighted) \
             (not drawn) learning rate halved × 0.25 lr no iterations no loss values to draw \
             0123456789",
            decade_label(-1234567890),
            scientific(2.5e-4),
            LossTerms::NAMES.concat()
        );
        for c in written.chars() {
            assert!(
                c == ' ' || font.glyph_id(c).0 != 0,
                "{c:?} is not in the embedded font"
            );
        }
    }

    #[test]
    fn plot_has_axes_ticks_legend_and_text() {
        let img = loss_plot_image(&history(700), &OptimConfig::default()).unwrap();
        assert_eq!(img.dimensions(), PLOT_SIZE);
        let (w, h) = PLOT_SIZE;
        let chart_bottom = h - LEGEND_HEIGHT - X_LABEL_AREA;
        // The y tick labels and title, left of the y axis (and its tick marks): only text is
        // drawn there.
        let left = dark(
            &img,
            (0, Y_LABEL_AREA - 12),
            (CAPTION_AREA, chart_bottom),
            100,
        );
        assert!(left > 150, "{left} dark pixels left of the y axis");
        // The x tick labels and title, below the x axis and its tick marks.
        let below = dark(
            &img,
            (Y_LABEL_AREA + 20, w - 20),
            (chart_bottom + 8, h - LEGEND_HEIGHT),
            100,
        );
        assert!(below > 150, "{below} dark pixels under the x axis");
        // The caption.
        let caption = dark(&img, (Y_LABEL_AREA, w - 22), (0, CAPTION_AREA - 4), 100);
        assert!(caption > 150, "{caption} dark pixels in the caption");
        // Each legend entry (7 curves, the learning-rate steps) has its name written right of
        // its line sample; 170: the grey of a term that is not drawn (`alb` here) counts too.
        for i in 0..8 {
            let (x, y) = legend_slot(i);
            let n = dark(
                &img,
                ((x + LEGEND_TEXT) as u32, (x + LEGEND_COLUMN - 10) as u32),
                (y as u32, (y + LEGEND_ROW) as u32),
                170,
            );
            assert!(n > 15, "legend entry {i}: {n} dark pixels");
        }
        // Antialiased text: many grey levels, not just the grid's.
        let greys = img
            .pixels()
            .filter(|p| p.0[0] == p.0[1] && p.0[1] == p.0[2])
            .map(|p| p.0[0])
            .collect::<std::collections::BTreeSet<u8>>();
        assert!(
            greys.len() > 20,
            "{} grey levels: text not antialiased",
            greys.len()
        );
        // The curves: the loss's colours appear in the plotting area.
        let red = img.pixels().filter(|p| p.0 == [220, 50, 47]).count();
        assert!(red > 300, "{red} pixels of rec_fine's colour");
    }

    #[test]
    fn learning_rate_steps_are_dashed_lines() {
        let img = loss_plot_image(&history(700), &OptimConfig::default()).unwrap();
        let without = loss_plot_image(
            &history(700),
            &OptimConfig {
                decay_step: 0,
                ..OptimConfig::default()
            },
        )
        .unwrap();
        // The columns holding over 100 pixels of the step lines' grey, with those pixels' rows
        // (the rate labels, in the same grey, are short).
        let step_columns = |img: &image::RgbImage| -> Vec<(u32, Vec<u32>)> {
            let mut columns = std::collections::BTreeMap::<u32, Vec<u32>>::new();
            for (x, y, p) in img.enumerate_pixels() {
                if p.0 == [110, 110, 110] {
                    columns.entry(x).or_default().push(y);
                }
            }
            columns
                .into_iter()
                .filter(|(_, ys)| ys.len() > 100)
                .collect()
        };
        // Three lines (200, 400, 600 of 700 iterations, in order across the chart), each
        // dashed: the grey comes and goes along its column.
        let lines = step_columns(&img);
        assert_eq!(lines.len(), 3, "columns with a step line: {lines:?}");
        let (w, _) = PLOT_SIZE;
        let left = Y_LABEL_AREA as f64;
        let width = f64::from(w - 22) - left;
        for ((x, ys), step) in lines.iter().zip([200.0, 400.0, 600.0]) {
            let expected = left + width * step / 700.0;
            assert!(
                (f64::from(*x) - expected).abs() < 3.0,
                "line of iteration {step} at x = {x}, expected about {expected:.0}"
            );
            let gaps = ys.windows(2).filter(|p| p[1] > p[0] + 1).count();
            assert!(gaps > 10, "column {x}: {gaps} gaps, not dashed");
        }
        assert!(step_columns(&without).is_empty());
    }

    #[test]
    fn bad_values_and_empty_histories_still_plot() {
        let mut h = history(50);
        h[3].total = f64::NAN;
        h[4].rec_fine = f64::INFINITY;
        h[5].nv = 0.0;
        h[6].sym = -1.0;
        h[7] = terms(f64::NAN);
        let img = loss_plot_image(&h, &OptimConfig::default()).unwrap();
        assert_eq!(img.dimensions(), PLOT_SIZE);
        for bad in [
            vec![],
            vec![terms(f64::NAN); 3],
            vec![terms(0.0); 2],
            vec![terms(1.0)],
            vec![terms(f64::MIN_POSITIVE), terms(f64::MAX)],
            vec![terms(5e-324), terms(1e-300), terms(1e300), terms(-0.0)],
        ] {
            let img = loss_plot_image(&bad, &OptimConfig::default()).unwrap();
            assert_eq!(img.dimensions(), PLOT_SIZE);
        }
        // The empty plot says so in the middle of its plotting area.
        let img = loss_plot_image(&[], &OptimConfig::default()).unwrap();
        let (w, h) = PLOT_SIZE;
        let cx = (Y_LABEL_AREA + w - 22) / 2;
        let cy = (CAPTION_AREA + h - LEGEND_HEIGHT - X_LABEL_AREA) / 2;
        let n = dark(&img, (cx - 60, cx + 60), (cy - 15, cy + 15), 180);
        assert!(n > 50, "{n} dark pixels where the note should be");
    }

    #[test]
    fn write_loss_plot_writes_a_png_of_the_plot_size() {
        let dir = std::env::temp_dir().join(format!("bitt-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("loss.png");
        write_loss_plot(&path, &history(700), &OptimConfig::default()).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), PLOT_SIZE);
        if let Ok(copy) = std::env::var("BITT_LOSS_PLOT_COPY") {
            std::fs::copy(&path, copy).unwrap();
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
