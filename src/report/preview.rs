//! `preview.png`: one picture that shows at a glance whether a dance looks like dancing.
//!
//! From top to bottom ([`WIDTH`] × [`HEIGHT`] px):
//! - a title: model, seed, song, song duration, mean joint speed;
//! - [`FIGURES`] stick figures at instants spread over the whole dance, twice: seen from the
//!   dancer's front and from their right side (the view turns with the dancer's hips and
//!   shoulders, so a pose reads the same whichever way they face). All are drawn to one scale in
//!   world metres over the floor line (y = 0) with the ground shaded below it, so a dancer who
//!   floats or sinks is obvious; each is labelled with its time;
//! - mean joint speed (m/s) over the dance, with the music's beats as ticks along the top and
//!   key-pose times as vertical lines;
//! - the lowest foot point's height over the dance against the floor.
//!
//! # Font
//! Text needs a font file. plotters' default `ttf` feature looks fonts up through font-kit and
//! fontconfig, which would make the binary (and the container) depend on system libraries and
//! installed fonts, and the picture on which font a machine has. We use its `ab_glyph` feature
//! instead, with DejaVu Sans compiled in (`assets/fonts/DejaVuSans.ttf`; its licence, which
//! allows redistribution, is beside it): the picture needs nothing installed and is the same
//! everywhere.
use std::sync::OnceLock;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::metrics::musicality::Musicality;
use crate::motion::feet::floor_height;
use crate::motion::feet::SUPPORT_HEIGHT_M;
use crate::motion::skeleton::{
    body_centre, ANATOMICAL, FOOT_POINTS, HEAD, HIPS, PARENTS, SHOULDERS, SPINE,
};
use crate::motion::{Motion, NUM_JOINTS};

/// File name of the picture next to a dance's other results.
pub const PREVIEW_FILE: &str = "preview.png";
/// Picture width, px.
pub const WIDTH: u32 = 2000;
/// Picture height, px.
pub const HEIGHT: u32 = 1040;
/// Stick figures per view.
pub const FIGURES: usize = 12;

/// Height of the title band, px.
const TITLE_H: u32 = 44;
/// Height of one row of figures (figures and their time labels), px.
const ROW_H: u32 = 290;
/// Height of the time label under each figure, px.
const LABEL_H: i32 = 22;
/// Left margin of the figure rows, for the row name and the height scale, px.
const ROW_LEFT: i32 = 96;
/// Height of the speed plot, px (the foot plot takes the rest).
const SPEED_H: u32 = 230;
/// Smoothing window of the speed curve drawn over the raw one, seconds.
const SMOOTH_S: f64 = 0.5;
/// Radius of the head circle, metres.
const HEAD_RADIUS_M: f64 = 0.1;

const FONT_FAMILY: &str = "sans-serif";
/// DejaVu Sans (see the module doc for why it is compiled in).
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// The body's right side (joints 3–11 and the right hand point).
const RIGHT: RGBColor = RGBColor(214, 39, 40);
/// The body's left side (joints 12–21).
const LEFT: RGBColor = RGBColor(31, 119, 180);
/// Head and spine.
const CENTRE: RGBColor = RGBColor(40, 40, 40);
/// The floor line, y = 0.
const FLOOR: RGBColor = RGBColor(139, 90, 43);
/// The ground below the floor line.
const GROUND: RGBColor = RGBColor(240, 228, 210);
/// Height grid lines (1 m, 2 m) and cell separators.
const GRID: RGBColor = RGBColor(222, 222, 222);
/// Music beats.
const BEAT: RGBColor = RGBColor(230, 120, 0);
/// Key poses.
const KEY: RGBColor = RGBColor(0, 150, 60);
/// The raw speed curve (the smoothed one is [`LEFT`]).
const RAW: RGBColor = RGBColor(170, 195, 225);

/// Who made the dance, for the title.
#[derive(Clone, Debug)]
pub struct Caption {
    /// Model id.
    pub model: String,
    /// The seed the dance was generated with.
    pub seed: u64,
    /// The song's name, where one is known (a file name or a test dance id).
    pub song: Option<String>,
    /// The dance style, where the model danced one (and whether it chose it from the song).
    pub style: Option<crate::models::StyleChoice>,
}

/// Everything the picture shows.
#[derive(Clone, Copy, Debug)]
pub struct Sheet<'a> {
    /// The dance: world metres, y up.
    pub motion: &'a Motion,
    /// Music beat times (s) on the dance's clock.
    pub beat_times: &'a [f64],
    /// Key-pose times (s) on the dance's clock.
    pub key_pose_times: &'a [f64],
    /// Length of the song (s); the dance may be a frame shorter.
    pub song_duration_s: f64,
    pub caption: &'a Caption,
    /// The dance's musicality as its report gives it ([`crate::metrics::score`]), for the
    /// title: measured once, where the report scores the dance, not again here.
    pub musicality: &'a Musicality,
}

/// What can stop a preview from being drawn.
#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    #[error("the dance has no frames")]
    Empty,
    #[error("the dance has {0} joints, the preview draws {NUM_JOINTS}")]
    Joints(usize),
    #[error("the frame rate {0} is not a positive number")]
    Fps(f64),
    #[error("the embedded font did not load: {0}")]
    Font(String),
    #[error("drawing failed: {0}")]
    Draw(String),
    #[error("PNG encoding failed: {0}")]
    Encode(#[from] png::EncodingError),
    #[error("cannot write {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
}

impl PreviewError {
    /// Stable kebab-case name of the failure.
    pub fn code(&self) -> &'static str {
        match self {
            PreviewError::Empty => "preview-empty",
            PreviewError::Joints(_) => "preview-joints",
            PreviewError::Fps(_) => "preview-fps",
            PreviewError::Font(_) => "preview-font",
            PreviewError::Draw(_) => "preview-draw",
            PreviewError::Encode(_) => "preview-encode",
            PreviewError::Io { .. } => "preview-io",
        }
    }
}

impl<E: std::error::Error + Send + Sync> From<DrawingAreaErrorKind<E>> for PreviewError {
    fn from(e: DrawingAreaErrorKind<E>) -> Self {
        PreviewError::Draw(e.to_string())
    }
}

/// Registers the embedded font once per process; plotters looks text up by family name.
fn ensure_font() -> Result<(), PreviewError> {
    static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, FONT)
                .map_err(|_| "DejaVu Sans is not a valid font".to_string())
        })
        .clone()
        .map_err(PreviewError::Font)
}

/// The picture as PNG bytes.
pub fn render_png(sheet: &Sheet<'_>) -> Result<Vec<u8>, PreviewError> {
    let rgb = render_rgb(sheet)?;
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, WIDTH, HEIGHT);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    // Flat colours and thin lines compress best unfiltered: on a real 76-s dance 169 kB in 0.11 s,
    // against 216 kB with the default filter and 163 kB in 0.20 s at the Best level.
    encoder.set_compression(png::Compression::Default);
    encoder.set_filter(png::FilterType::NoFilter);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(&rgb)?;
    writer.finish()?;
    Ok(out)
}

/// The picture as 8-bit RGB pixels, row by row.
pub fn render_rgb(sheet: &Sheet<'_>) -> Result<Vec<u8>, PreviewError> {
    let motion = sheet.motion;
    let (frames, joints, _) = motion.positions.dim();
    if frames == 0 {
        return Err(PreviewError::Empty);
    }
    if joints != NUM_JOINTS {
        return Err(PreviewError::Joints(joints));
    }
    if !(motion.fps.is_finite() && motion.fps > 0.0) {
        return Err(PreviewError::Fps(motion.fps));
    }
    ensure_font()?;
    let series = Series::of(motion);
    let mut rgb = vec![255u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let (title, rest) = root.split_vertically(TITLE_H);
        let (front, rest) = rest.split_vertically(ROW_H);
        let (side, rest) = rest.split_vertically(ROW_H);
        let (speed, feet) = rest.split_vertically(SPEED_H);
        draw_title(&title, sheet, &series)?;
        let rows = FigureRows::new(motion);
        rows.draw(&front, motion, View::Front)?;
        rows.draw(&side, motion, View::Side)?;
        draw_speed(&speed, sheet, &series, &rows.frames)?;
        draw_feet(
            &feet,
            &series,
            motion.duration_s(),
            floor_height(motion.positions.view(), &FOOT_POINTS),
        )?;
        root.present()?;
    }
    Ok(rgb)
}

/// Writes the picture to `path` (not atomically: jobs go through the exporter's atomic writer).
pub fn write_png(path: &std::path::Path, sheet: &Sheet<'_>) -> Result<(), PreviewError> {
    let bytes = render_png(sheet)?;
    std::fs::write(path, bytes).map_err(|source| PreviewError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// The time series the plots and the title show.
struct Series {
    /// Mean speed of the anatomical joints (m/s) between frames t−1 and t, at the midpoint time.
    speed: Vec<(f64, f64)>,
    /// Height (m) of the lowest foot point of each frame.
    lowest_foot: Vec<(f64, f64)>,
    /// Mean of `speed` (m/s); NaN for a one-frame dance.
    mean_speed: f64,
}

impl Series {
    fn of(motion: &Motion) -> Self {
        let p = &motion.positions;
        let fps = motion.fps;
        let t = p.dim().0;
        let speed: Vec<(f64, f64)> = (1..t)
            .map(|f| {
                let sum: f64 = ANATOMICAL
                    .iter()
                    .map(|&j| {
                        let d: f64 = (0..3)
                            .map(|k| f64::from(p[[f, j, k]] - p[[f - 1, j, k]]).powi(2))
                            .sum();
                        d.sqrt()
                    })
                    .sum();
                ((f as f64 - 0.5) / fps, sum / ANATOMICAL.len() as f64 * fps)
            })
            .filter(|(_, v)| v.is_finite())
            .collect();
        let lowest_foot = crate::motion::feet::lowest_foot(p.view(), &FOOT_POINTS)
            .into_iter()
            .enumerate()
            .map(|(f, y)| (f as f64 / fps, y))
            .filter(|(_, y)| y.is_finite())
            .collect();
        let mean_speed = if speed.is_empty() {
            f64::NAN
        } else {
            speed.iter().map(|(_, v)| v).sum::<f64>() / speed.len() as f64
        };
        Series {
            speed,
            lowest_foot,
            mean_speed,
        }
    }
}

/// The `q`th quantile (0–1) of `values` (nearest rank); NaN when empty.
fn quantile(values: impl Iterator<Item = f64>, q: f64) -> f64 {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn font(size: u32) -> TextStyle<'static> {
    (FONT_FAMILY, size).into_font().color(&BLACK)
}

fn clock(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    format!("{}:{:02}", s / 60, s % 60)
}

fn draw_title<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    sheet: &Sheet<'_>,
    series: &Series,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let c = sheet.caption;
    let mut parts = vec![c.model.clone(), format!("seed {}", c.seed)];
    if let Some(s) = &c.style {
        parts.push(format!(
            "{}{}",
            s.style.name(),
            if s.predicted { " (from the song)" } else { "" }
        ));
    }
    if let Some(song) = &c.song {
        // The name is the user's: keep it to one line.
        let song: String = song
            .chars()
            .filter(|ch| !ch.is_control())
            .take(60)
            .collect();
        parts.push(song);
    }
    parts.push(format!(
        "song {} ({:.1} s)",
        clock(sheet.song_duration_s),
        sheet.song_duration_s
    ));
    parts.push(format!("mean joint speed {:.2} m/s", series.mean_speed));
    // Does it go with this song: the step rate against the beat, the arms, a hold.
    let m = sheet.musicality;
    if let Some(lock) = m.tempo_lock {
        let mark = if lock.locked { "locked" } else { "off" };
        parts.push(format!(
            "steps {:.2}× beat ({mark}, {:+.0} % from {})",
            lock.ratio,
            100.0 * (lock.ratio / lock.fraction - 1.0),
            crate::metrics::musicality::fraction_name(lock.fraction)
        ));
    }
    parts.push(format!("arms {:.2} m/s", m.arm_speed_m_s));
    // A stand the eye may miss between the sheet's sampled frames.
    if m.longest_hold_s >= crate::motion::hold::HOLD_NOTED_S {
        parts.push(format!("holds {:.0} s", m.longest_hold_s));
    }
    area.draw_text(
        &parts.join("  ·  "),
        &font(24).pos(Pos::new(HPos::Left, VPos::Center)),
        (16, TITLE_H as i32 / 2),
    )
}

/// Which way a row of figures looks at the dancer.
#[derive(Clone, Copy, Debug, PartialEq)]
enum View {
    /// From in front of the dancer: their left on the picture's right.
    Front,
    /// From the dancer's right side: they face the picture's right.
    Side,
}

/// The instants the figures show and the scale they share.
struct FigureRows {
    /// Frame of each figure.
    frames: Vec<usize>,
    /// Lowest and highest height shown (m); the floor (0) is always inside.
    y_range: (f64, f64),
}

impl FigureRows {
    fn new(motion: &Motion) -> Self {
        let t = motion.num_frames();
        let n = FIGURES.min(t);
        // The middle of each of n equal spans: the whole dance, evenly.
        let frames: Vec<usize> = (0..n)
            .map(|i| (((i as f64 + 0.5) * t as f64 / n as f64) as usize).min(t - 1))
            .collect();
        let heights = frames
            .iter()
            .flat_map(|&f| (0..NUM_JOINTS).map(move |j| f64::from(motion.positions[[f, j, 1]])));
        let (lo, hi) = heights
            .filter(|y| y.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
                (lo.min(y), hi.max(y))
            });
        // A standing dancer and some ground fit by default; a floating or sunken one widens it.
        let y_range = ((lo - 0.1).min(-0.25), (hi + 0.15).max(2.0));
        FigureRows { frames, y_range }
    }

    fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        motion: &Motion,
        view: View,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let (w, h) = area.dim_in_pixel();
        let (w, h) = (w as i32, h as i32);
        let top = 6;
        let fig_h = h - LABEL_H - top;
        let (y_lo, y_hi) = self.y_range;
        let ppm = f64::from(fig_h) / (y_hi - y_lo);
        let row_y = |y: f64| top + ((y_hi - y) * ppm).round() as i32;
        let cell_w = (w - ROW_LEFT - 8) / FIGURES as i32;

        // Ground, floor line and height grid across the whole row.
        area.draw(&Rectangle::new(
            [(ROW_LEFT, row_y(0.0)), (w - 8, top + fig_h)],
            GROUND.filled(),
        ))?;
        for metres in [1.0, 2.0] {
            if metres < y_hi {
                area.draw(&PathElement::new(
                    vec![(ROW_LEFT, row_y(metres)), (w - 8, row_y(metres))],
                    GRID.stroke_width(1),
                ))?;
                area.draw_text(
                    &format!("{metres:.0} m"),
                    &font(14).pos(Pos::new(HPos::Right, VPos::Center)),
                    (ROW_LEFT - 6, row_y(metres)),
                )?;
            }
        }
        area.draw(&PathElement::new(
            vec![(ROW_LEFT, row_y(0.0)), (w - 8, row_y(0.0))],
            FLOOR.stroke_width(2),
        ))?;
        area.draw_text(
            "floor 0 m",
            &font(14)
                .color(&FLOOR)
                .pos(Pos::new(HPos::Right, VPos::Center)),
            (ROW_LEFT - 6, row_y(0.0)),
        )?;
        let name = match view {
            View::Front => "front",
            View::Side => "side (from right)",
        };
        area.draw_text(
            name,
            &font(16).pos(Pos::new(HPos::Left, VPos::Top)),
            (8, top),
        )?;
        for i in 1..FIGURES as i32 {
            let x = ROW_LEFT + i * cell_w;
            area.draw(&PathElement::new(
                vec![(x, top), (x, row_y(0.0))],
                GRID.stroke_width(1),
            ))?;
        }

        for (i, &f) in self.frames.iter().enumerate() {
            let centre_x = ROW_LEFT + i as i32 * cell_w + cell_w / 2;
            let frame = motion.positions.index_axis(ndarray::Axis(0), f);
            let points = project(frame, view);
            let px = |k: usize| -> Option<(i32, i32)> {
                let (x, y) = points[k];
                (x.is_finite() && y.is_finite())
                    .then(|| (centre_x + (x * ppm).round() as i32, row_y(y)))
            };
            // Torso lines first, then limbs, so the limbs' sides stay visible. The two head
            // markers become one head (a circle at their midpoint) on a neck from the spine.
            let mut segments: Vec<(usize, usize, RGBColor)> = vec![
                (HIPS[0], HIPS[1], CENTRE),
                (SHOULDERS[0], SHOULDERS[1], CENTRE),
            ];
            segments.extend(
                (0..NUM_JOINTS)
                    .filter(|c| !HEAD.contains(c))
                    .filter_map(|c| PARENTS[c].map(|p| (p, c, side_colour(c)))),
            );
            for (a, b, colour) in segments {
                if let (Some(pa), Some(pb)) = (px(a), px(b)) {
                    area.draw(&PathElement::new(vec![pa, pb], colour.stroke_width(3)))?;
                }
            }
            if let (Some(a), Some(b), Some(spine)) = (px(HEAD[0]), px(HEAD[1]), px(SPINE)) {
                let head = ((a.0 + b.0) / 2, (a.1 + b.1) / 2);
                let radius = (HEAD_RADIUS_M * ppm).round().max(2.0);
                // The neck stops at the circle.
                let (dx, dy) = (f64::from(spine.0 - head.0), f64::from(spine.1 - head.1));
                let len = dx.hypot(dy);
                if len > radius {
                    let rim = (
                        head.0 + (dx / len * radius).round() as i32,
                        head.1 + (dy / len * radius).round() as i32,
                    );
                    area.draw(&PathElement::new(vec![spine, rim], CENTRE.stroke_width(3)))?;
                }
                area.draw(&Circle::new(head, radius as i32, CENTRE.stroke_width(2)))?;
            }
            let seconds = f as f64 / motion.fps;
            area.draw_text(
                &format!("{seconds:.1} s"),
                &font(15).pos(Pos::new(HPos::Center, VPos::Bottom)),
                (centre_x, h - 2),
            )?;
        }
        Ok(())
    }
}

/// The colour of the bone ending at joint `j`: right side red, left side blue, centre dark.
fn side_colour(j: usize) -> RGBColor {
    match j {
        3..=11 | 22 => RIGHT,
        12..=21 => LEFT,
        _ => CENTRE,
    }
}

/// Joint positions of one frame `[J, 3]` as (across, up) metres in `view`: across measured from
/// the body centre along the dancer's own left (front view) or forward (side view) direction,
/// up as the world's y, so the floor stays at 0.
fn project(frame: ndarray::ArrayView2<'_, f32>, view: View) -> Vec<(f64, f64)> {
    let at = |j: usize| [0, 1, 2].map(|k| f64::from(frame[[j, k]]));
    let root = body_centre(frame).map(f64::from);
    // The dancer's left: from the right hip and shoulder to the left ones, made horizontal.
    let (rh, lh, rs, ls) = (at(HIPS[0]), at(HIPS[1]), at(SHOULDERS[0]), at(SHOULDERS[1]));
    let (mut lx, mut lz) = (lh[0] - rh[0] + ls[0] - rs[0], lh[2] - rh[2] + ls[2] - rs[2]);
    let norm = lx.hypot(lz);
    if norm > 1e-6 && norm.is_finite() {
        (lx, lz) = (lx / norm, lz / norm);
    } else {
        (lx, lz) = (1.0, 0.0); // lying flat along the hips: fall back to the world's x
    }
    // y up, right-handed: forward = left × up.
    let (fx, fz) = (-lz, lx);
    let (ax, az) = match view {
        View::Front => (lx, lz),
        View::Side => (fx, fz),
    };
    (0..frame.dim().0)
        .map(|j| {
            let p = at(j);
            ((p[0] - root[0]) * ax + (p[2] - root[2]) * az, p[1])
        })
        .collect()
}

/// A plot with a linear f64 axis each way.
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Shared margins of the two plots, so their time axes line up.
fn plot<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> Result<Chart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let mut chart = ChartBuilder::on(area)
        .margin_left(16)
        .margin_right(24)
        .margin_top(6)
        .caption(caption, font(17))
        .x_label_area_size(38)
        .y_label_area_size(70)
        .build_cartesian_2d(x, y)?;
    chart
        .configure_mesh()
        .light_line_style(RGBColor(242, 242, 242))
        .bold_line_style(GRID)
        .x_desc("time (s)")
        .label_style(font(14))
        .axis_desc_style(font(14))
        .x_labels(20)
        .y_labels(6)
        .draw()?;
    Ok(chart)
}

/// Moving average of `v` over `window` samples, centred.
fn smooth(v: &[(f64, f64)], window: usize) -> Vec<(f64, f64)> {
    let half = window / 2;
    (0..v.len())
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + half + 1).min(v.len()));
            (
                v[i].0,
                v[a..b].iter().map(|p| p.1).sum::<f64>() / (b - a) as f64,
            )
        })
        .collect()
}

fn draw_speed<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    sheet: &Sheet<'_>,
    series: &Series,
    figure_frames: &[usize],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let duration = sheet.motion.duration_s().max(1.0 / sheet.motion.fps);
    // A glitch should not flatten the curve: the top is a high quantile, spikes are cut there.
    let top = (quantile(series.speed.iter().map(|p| p.1), 0.995) * 1.25).max(0.2);
    let top = if top.is_finite() { top } else { 1.0 };
    let caption = if sheet.key_pose_times.is_empty() {
        "mean joint speed (m/s): raw light, 0.5 s average dark · orange ticks: music beats · grey: the figures' instants".to_string()
    } else {
        "mean joint speed (m/s): raw light, 0.5 s average dark · orange ticks: music beats · green lines: key poses · grey: the figures' instants".to_string()
    };
    let mut chart = plot(area, &caption, 0.0..duration, 0.0..top)?;
    let clip = |(t, v): (f64, f64)| (t, v.min(top));
    chart.draw_series(LineSeries::new(
        series.speed.iter().copied().map(clip),
        RAW.stroke_width(1),
    ))?;
    let window = (SMOOTH_S * sheet.motion.fps).round().max(1.0) as usize;
    chart.draw_series(LineSeries::new(
        smooth(&series.speed, window).into_iter().map(clip),
        LEFT.stroke_width(2),
    ))?;
    let inside = |t: &&f64| t.is_finite() && (0.0..=duration).contains(*t);
    chart.draw_series(
        sheet
            .beat_times
            .iter()
            .filter(inside)
            .map(|&b| PathElement::new(vec![(b, top), (b, top * 0.9)], BEAT.stroke_width(2))),
    )?;
    chart.draw_series(
        sheet
            .key_pose_times
            .iter()
            .filter(inside)
            .map(|&k| PathElement::new(vec![(k, 0.0), (k, top)], KEY.stroke_width(2))),
    )?;
    chart.draw_series(
        figure_frames
            .iter()
            .map(|&f| f as f64 / sheet.motion.fps)
            .map(|t| {
                PathElement::new(
                    vec![(t, 0.0), (t, top * 0.06)],
                    RGBColor(120, 120, 120).stroke_width(3),
                )
            }),
    )?;
    Ok(())
}

/// The lowest foot's height over time; `rest` is where the dance's own floor is
/// ([`floor_height`]: feet rest there, whatever y = 0 says).
fn draw_feet<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    series: &Series,
    duration: f64,
    rest: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let duration = duration.max(1e-3);
    let heights = || series.lowest_foot.iter().map(|p| p.1);
    let lo = heights().fold(f64::INFINITY, f64::min);
    let hi = quantile(heights(), 0.995);
    let (lo, hi) = if lo.is_finite() && hi.is_finite() {
        ((lo - 0.05).min(-0.1), (hi + 0.05).max(0.4))
    } else {
        (-0.1, 0.4)
    };
    let on_floor = heights().filter(|y| y.abs() <= SUPPORT_HEIGHT_M).count() as f64
        / series.lowest_foot.len().max(1) as f64;
    let caption = format!(
        "lowest foot point height (m) · brown: the floor (y = 0), within {:.0} cm of it {:.0} % of the time · grey dashes: where this dance's feet rest ({:+.1} cm)",
        SUPPORT_HEIGHT_M * 100.0,
        on_floor * 100.0,
        // Rounded first, so a floor 0.3 mm below zero does not print as "-0.0".
        (rest * 1000.0).round() / 10.0 + 0.0
    );
    let mut chart = plot(area, &caption, 0.0..duration, lo..hi)?;
    chart.draw_series(std::iter::once(Rectangle::new(
        [(0.0, lo), (duration, 0.0)],
        GROUND.filled(),
    )))?;
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(0.0, 0.0), (duration, 0.0)],
        FLOOR.stroke_width(2),
    )))?;
    if rest.is_finite() {
        let dash = duration / 150.0;
        chart.draw_series((0..150).step_by(2).map(|i| {
            let t = i as f64 * dash;
            PathElement::new(
                vec![(t, rest), (t + dash, rest)],
                RGBColor(110, 110, 110).stroke_width(2),
            )
        }))?;
    }
    chart.draw_series(LineSeries::new(
        series.lowest_foot.iter().map(|&(t, y)| (t, y.min(hi))),
        CENTRE.stroke_width(1),
    ))?;
    Ok(())
}

#[cfg(test)]
mod tests;
