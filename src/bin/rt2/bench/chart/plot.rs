//! The chart of `rt2 bench chart` (docs/chart.svg and docs/chart.png), drawn with plotters.

use super::{fronts, sets_of, Engine, Point};
use plotters::coord::Shift;
use plotters::element::ComposedElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use rt2::cpu::query::QueryMode;
use std::error::Error;
use std::path::Path;

/// Zero failures are drawn here on the log axis (and labelled "0" in the axis text).
const FLOOR: f64 = 0.1;

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// A filled polygon and its outline, in pixels around a point.
type Marker<C, DB> = ComposedElement<C, DB, Polygon<(i32, i32)>, PathElement<(i32, i32)>>;

/// The marker of a point of `engine`: circle (one ray at a time), triangle (packets),
/// square (streams), diamond (GPU); filled for the watertight test. One element type for
/// every engine (a polygon and its outline, in pixels around the point), so one series and
/// one legend entry draw any of them.
fn marker<DB: DrawingBackend, C>(
    engine: Engine,
    at: C,
    color: RGBColor,
    filled: bool,
) -> Marker<C, DB> {
    let corners: Vec<(i32, i32)> = match engine {
        Engine::Cpu(QueryMode::Single) => (0..16)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 16.0;
                (
                    (5.0 * a.cos()).round() as i32,
                    (5.0 * a.sin()).round() as i32,
                )
            })
            .collect(),
        Engine::Cpu(QueryMode::Packet) => vec![(0, -6), (5, 4), (-5, 4)],
        Engine::Cpu(QueryMode::Stream) => vec![(-4, -4), (4, -4), (4, 4), (-4, 4)],
        Engine::Gpu => vec![(0, -6), (6, 0), (0, 6), (-6, 0)],
    };
    let fill = if filled {
        color.filled()
    } else {
        TRANSPARENT.filled()
    };
    let mut outline = corners.clone();
    outline.push(corners[0]);
    EmptyElement::at(at)
        + Polygon::new(corners, fill)
        + PathElement::new(outline, color.stroke_width(2))
}

fn panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    points: &[Point],
    gpu: Option<&str>,
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    let x = |p: &Point| p.error.max(FLOOR);
    // The points take the left 58% of the log axis; the legend, the right 40%.
    let xmin = FLOOR * 0.7;
    let xmax = xmin * (points.iter().map(x).fold(10.0, f64::max) / xmin).powf(1.0 / 0.58);
    let ymax = points.iter().map(|p| p.mrays).fold(0.1, f64::max) * 1.15;
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(56)
        .build_cartesian_2d((xmin..xmax).log_scale(), 0.0..ymax)?;
    chart
        .configure_mesh()
        .x_desc("failures per million rays (log; 0 drawn at 0.1); lines: Pareto front per set")
        .x_label_formatter(&|v| {
            if *v >= 1e3 {
                format!("{v:.0e}")
            } else {
                format!("{v}")
            }
        })
        .y_desc("Mrays/s")
        .label_style(("sans-serif", 13))
        .draw()?;
    let all_fronts = fronts(points);
    for (k, (set, front)) in sets_of(points).iter().zip(&all_fronts).enumerate() {
        let color = COLORS[k % COLORS.len()];
        let watertight = |p: &Point| p.method.contains("watertight");
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.set == *set)
                    .map(|p| marker(p.engine, (x(p), p.mrays), color, watertight(p))),
            )?
            .label(format!("{set} (filled: watertight)"))
            .legend(move |(lx, ly)| Circle::new((lx, ly), 5, color.filled()));
        // The set's Pareto front: a line through it.
        chart.draw_series(LineSeries::new(
            front.iter().map(|p| (x(p), p.mrays)),
            color.stroke_width(2),
        ))?;
    }
    // Each front point named: right of points near the left edge, left of the others
    // (names never reach the legend's side); moved up or down, nearest first, off the
    // names already placed.
    let mut placed: Vec<(i32, i32, i32, i32)> = Vec::new();
    for p in all_fronts.iter().flatten() {
        let (px, py) = chart.backend_coord(&(x(p), p.mrays));
        let left_edge = (x(p) / xmin).ln() / (xmax / xmin).ln() < 0.3;
        let (dx, h) = if left_edge {
            (9, HPos::Left)
        } else {
            (-9, HPos::Right)
        };
        let font = TextStyle::from(("sans-serif", 12).into_font()).pos(Pos::new(h, VPos::Center));
        let (w, th) = area.estimate_text_size(&p.method, &font)?;
        let (w, th) = (w as i32, th as i32 + 2);
        let x0 = if left_edge { px + dx } else { px + dx - w };
        let rect = |dy: i32| (x0, py + dy - th / 2, x0 + w, py + dy + th / 2);
        let free = |r: (i32, i32, i32, i32)| {
            placed
                .iter()
                .all(|q| r.2 <= q.0 || q.2 <= r.0 || r.3 <= q.1 || q.3 <= r.1)
        };
        // 0, -th, th, -2th, 2th, ...
        let dy = (0..9)
            .map(|i| th * ((i + 1) / 2) * if i % 2 == 0 { 1 } else { -1 })
            .find(|&d| free(rect(d)))
            .unwrap_or(0);
        placed.push(rect(dy));
        chart.draw_series(std::iter::once(
            EmptyElement::at((x(p), p.mrays)) + Text::new(p.method.clone(), (dx, dy), font),
        ))?;
    }
    // One legend entry per engine present: its marker in black.
    for engine in Engine::ALL {
        if !points.iter().any(|p| p.engine == engine) {
            continue;
        }
        let name = match engine {
            Engine::Cpu(QueryMode::Single) => "one ray at a time".to_string(),
            Engine::Cpu(QueryMode::Packet) => "packets (standard order)".to_string(),
            Engine::Cpu(QueryMode::Stream) => "streams (standard order)".to_string(),
            Engine::Gpu => format!("gpu: {}", gpu.unwrap_or("adapter")),
        };
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
            .label(name)
            .legend(move |at| marker(engine, at, BLACK, false));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font(("sans-serif", 13))
        .border_style(BLACK)
        .background_style(WHITE.mix(0.85))
        .draw()?;
    Ok(())
}

fn all<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    panels: &[(&str, &Vec<Point>)],
    gpu: Option<&str>,
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    for (area, (title, points)) in root.split_evenly((1, panels.len())).iter().zip(panels) {
        panel(area, title, points, gpu)?;
    }
    root.present()?;
    Ok(())
}

/// Writes docs/chart.svg and docs/chart.png. Text needs a TTF font: `$RT2_FONT` or
/// DejaVu Sans where Debian and Ubuntu put it.
pub(super) fn draw(
    panels: &[(&str, &Vec<Point>)],
    gpu: Option<&str>,
) -> Result<(), Box<dyn Error>> {
    let font = std::env::var("RT2_FONT")
        .unwrap_or_else(|_| "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf".into());
    let bytes = std::fs::read(&font).map_err(|e| format!("font {font}: {e} (set RT2_FONT)"))?;
    plotters::style::register_font("sans-serif", FontStyle::Normal, Box::leak(bytes.into()))
        .map_err(|_| format!("{font} is not a usable TTF font"))?;
    std::fs::create_dir_all("docs")?;
    let size = (1500u32, 650u32);
    all(
        SVGBackend::new(Path::new("docs/chart.svg"), size).into_drawing_area(),
        panels,
        gpu,
    )?;
    let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
    all(
        BitMapBackend::with_buffer(&mut buf, size).into_drawing_area(),
        panels,
        gpu,
    )?;
    image::RgbImage::from_raw(size.0, size.1, buf)
        .ok_or("PNG buffer size")?
        .save("docs/chart.png")?;
    Ok(())
}
