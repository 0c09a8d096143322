//! The bench's plots, each as PNG and SVG: error against time with the Pareto front, the stage
//! breakdown per configuration (the paper's Table 2 as bars) and how time grows with the VAL
//! count, the sparse point count and the pixel count (log axes).
//!
//! Text is drawn with DejaVu Sans embedded in the binary (`assets/fonts/`): plotters' bitmap
//! backend has no system font lookup.

use super::{BenchResults, ConfigResult};
use crate::scene::Occlusion;
use plotters::coord::Shift;
use plotters::coord::combinators::LogCoord;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
const FAMILY: &str = "sans-serif";

type Drawn = Result<(), String>;

fn register_font() -> Drawn {
    static REGISTERED: OnceLock<Drawn> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FAMILY, FontStyle::Normal, FONT)
                .map_err(|_| "the embedded font (assets/fonts/DejaVuSans.ttf) does not parse".to_owned())
        })
        .clone()
}

/// The boxed legend of the labelled series, at `position`.
fn draw_legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Drawn {
    chart
        .configure_series_labels()
        .position(position)
        .border_style(BLACK)
        .background_style(WHITE.mix(0.85))
        .label_font((FAMILY, 12))
        .draw()
        .map_err(err)
}

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// Draw `$draw(&area, results)` into `<dir>/<name>.png` and `.svg`.
macro_rules! png_and_svg {
    ($dir:expr, $name:expr, $size:expr, $draw:ident, $results:expr) => {{
        let png = $dir.join(format!("{}.png", $name));
        let root = BitMapBackend::new(&png, $size).into_drawing_area();
        $draw(&root, $results)?;
        root.present().map_err(|e| format!("{}: {e}", png.display()))?;
        let svg = $dir.join(format!("{}.svg", $name));
        let root = SVGBackend::new(&svg, $size).into_drawing_area();
        $draw(&root, $results)?;
        root.present().map_err(|e| format!("{}: {e}", svg.display()))?;
    }};
}

/// The files [`write_all`] always writes, without extension (and `error_vs_time_exact` with an
/// exact reference).
pub const PLOTS: &[&str] = &["error_vs_time", "stage_breakdown", "scaling"];

/// Every plot, PNG and SVG, into `dir`.
pub fn write_all(dir: &Path, results: &BenchResults) -> Drawn {
    register_font()?;
    png_and_svg!(dir, PLOTS[0], (900, 600), draw_error_vs_time, results);
    if results.configs.iter().any(|r| r.vs_exact.is_some()) {
        png_and_svg!(dir, "error_vs_time_exact", (900, 600), draw_error_vs_time_exact, results);
    }
    let width = (300 + 60 * results.configs.len() as u32).clamp(900, 2400);
    png_and_svg!(dir, PLOTS[1], (width, 600), draw_stage_breakdown, results);
    png_and_svg!(dir, PLOTS[2], (1500, 500), draw_scaling, results);
    Ok(())
}

/// A short label: `s<sparse per mesh> R<rsm> <visibility> <glossy> <W>x<H>`, the visibility
/// mode's name when it is on, with an ism configuration's overrides (`ism m1024 r64 p800 pp2`).
fn short_label(r: &ConfigResult) -> String {
    let c = &r.config;
    let visibility = match c.occlusion {
        Occlusion::Off => String::new(),
        Occlusion::Ism => {
            let part = |prefix: &str, v: Option<u32>| v.map_or(String::new(), |n| format!(" {prefix}{n}"));
            format!(
                " ism{}{}{}{}",
                part("m", c.ism_count),
                part("r", c.ism_resolution),
                part("p", c.ism_points),
                part("pp", c.ism_pull_push_levels)
            )
        }
        mode => format!(" {}", mode.name()),
    };
    format!(
        "s{} R{}{}{} {}x{}",
        c.sparse_points_per_mesh.map_or("*".to_owned(), |n| n.to_string()),
        c.rsm_resolution,
        visibility,
        if c.glossy { "" } else { " noglossy" },
        c.width,
        c.height
    )
}

/// Indices of the configurations no other one beats in both time and error, by time.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0).then(points[a].1.total_cmp(&points[b].1)));
    let mut best = f64::INFINITY;
    let mut front = Vec::new();
    for i in order {
        if points[i].1 < best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

/// Positive range around `values` with a margin, for log axes.
fn log_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if hi <= 0.0 { 0.1..10.0 } else { lo / 1.5..hi * 1.5 }
}

/// A chart of an error (from 0 to `y_max`) over a time (`x_range`, ms, log axis), its mesh and
/// axis labels drawn.
fn error_over_time<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    caption: &str,
    (x_range, y_max): (std::ops::Range<f64>, f64),
    x_desc: &str,
    y_desc: &str,
) -> Result<ChartContext<'a, DB, Cartesian2d<LogCoord<f64>, RangedCoordf64>>, String> {
    let mut chart = ChartBuilder::on(root)
        .caption(caption, (FAMILY, 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(x_range.log_scale(), 0.0..y_max)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_labels(8)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style((FAMILY, 13))
        .draw()
        .map_err(err)?;
    Ok(chart)
}

fn draw_error_vs_time<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, results: &BenchResults) -> Drawn {
    draw_error_vs_time_against(root, results, false)
}

fn draw_error_vs_time_exact<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, results: &BenchResults) -> Drawn {
    draw_error_vs_time_against(root, results, true)
}

/// Error against brute force, or with `exact` against exact visibility, over time.
fn draw_error_vs_time_against<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    results: &BenchResults,
    exact: bool,
) -> Drawn {
    root.fill(&WHITE).map_err(err)?;
    // Against exact, the error with the reference's noise taken out where it is known, as the
    // converging estimator's curve is measured.
    let error = |r: &ConfigResult| match exact {
        true => r.error_vs_exact(),
        false => r.vs_brute_force.map(|e| e.rel_rmse),
    };
    let curves: Vec<Vec<(f64, f64)>> = match exact {
        true => results
            .equal_error_curves
            .iter()
            .map(|c| c.points.iter().map(|p| (p.ms, p.rel_rmse)).filter(|p| p.0 > 0.0 && p.1.is_finite()).collect())
            .collect(),
        false => Vec::new(),
    };
    let with_error: Vec<&ConfigResult> = results.configs.iter().filter(|r| error(r).is_some()).collect();
    let points: Vec<(f64, f64)> =
        with_error.iter().map(|r| (r.sparse_indirect_ms, error(r).unwrap_or_default())).collect();
    // The per-pixel ISM points (`brute_force_ism`), beside the sparse configurations: not on
    // the sparse method's front.
    let per_pixel: Vec<(f64, f64, String)> = results
        .brute_force_ism
        .iter()
        .filter_map(|r| {
            let e = match exact {
                true => r.error_vs_exact(),
                false => r.vs_brute_force.map(|e| e.rel_rmse),
            }?;
            let c = &r.config;
            let label = format!(
                "per-pixel ism m{} r{} pp{} {}x{}",
                r.ism.count, r.ism.resolution, r.ism.pull_push_levels, c.width, c.height
            );
            Some((r.indirect_ms, e, label))
        })
        .collect();
    let front = pareto_front(&points);
    let y_max = points
        .iter()
        .map(|p| p.1)
        .chain(per_pixel.iter().map(|p| p.1))
        .filter(|y| y.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-3)
        * 1.15;
    let x_range =
        log_range(points.iter().chain(curves.iter().flatten()).map(|p| p.0).chain(per_pixel.iter().map(|p| p.0)));
    let reference = match (exact, results.exact_val_stride) {
        (true, Some(n)) if n > 1 => format!("exact visibility (every {n}th VAL)"),
        (true, _) => "exact visibility".to_owned(),
        (false, _) => "brute force".to_owned(),
    };
    let mut chart = error_over_time(
        root,
        &format!("Indirect error against {reference} vs time ({})", results.adapter),
        (x_range, y_max),
        &format!("indirect stages, ms ({}, log)", results.timing.as_str()),
        "relative RMSE of the indirect image",
    )?;
    chart
        .draw_series(points.iter().map(|&p| Circle::new(p, 4, BLUE.mix(0.6).filled())))
        .map_err(err)?
        .label("configuration")
        .legend(|(x, y)| Circle::new((x + 5, y), 4, BLUE.mix(0.6).filled()));
    let front_points: Vec<(f64, f64)> = front.iter().map(|&i| points[i]).collect();
    chart
        .draw_series(LineSeries::new(front_points.clone(), RED.stroke_width(2)))
        .map_err(err)?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 15, y)], RED.stroke_width(2)));
    chart.draw_series(front_points.iter().map(|&p| Circle::new(p, 5, RED.filled()))).map_err(err)?;
    chart
        .draw_series(
            front
                .iter()
                .map(|&i| Text::new(short_label(with_error[i]), points[i], (FAMILY, 12).into_font().color(&BLACK))),
        )
        .map_err(err)?;
    if !per_pixel.is_empty() {
        let orange = RGBColor(255, 127, 14);
        chart
            .draw_series(per_pixel.iter().map(|p| TriangleMarker::new((p.0, p.1), 6, orange.filled())))
            .map_err(err)?
            .label("brute_force_ism (ISM lookup per pixel, no interpolation)")
            .legend(move |(x, y)| TriangleMarker::new((x + 5, y), 6, orange.filled()));
        chart
            .draw_series(
                per_pixel.iter().map(|p| Text::new(p.2.clone(), (p.0, p.1), (FAMILY, 12).into_font().color(&BLACK))),
            )
            .map_err(err)?;
    }
    let green = RGBColor(44, 160, 44);
    for (i, curve) in curves.iter().enumerate() {
        // The ladder's points within the configurations' error range (plotters draws points
        // outside the range at its edge).
        let curve: Vec<(f64, f64)> = curve.iter().copied().filter(|p| p.1 <= y_max).collect();
        let series = chart.draw_series(LineSeries::new(curve.clone(), green.stroke_width(2))).map_err(err)?;
        if i == 0 {
            series
                .label("converging estimator (exact, N importance-sampled VALs; CPU)")
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 15, y)], green.stroke_width(2)));
        }
        chart.draw_series(curve.iter().map(|&p| Cross::new(p, 4, green.stroke_width(2)))).map_err(err)?;
    }
    chart.configure_series_labels().border_style(BLACK).background_style(WHITE.mix(0.8)).draw().map_err(err)?;
    Ok(())
}

/// Stages in the order of a frame, and their colours.
const STAGES: &[(&str, RGBColor)] = &[
    ("rsm_raster", RGBColor(140, 86, 75)),
    ("rsm_vals", RGBColor(196, 156, 148)),
    ("visibility", RGBColor(127, 127, 127)),
    ("gather", RGBColor(31, 119, 180)),
    ("occlusion", RGBColor(214, 39, 40)),
    ("renormalise", RGBColor(255, 127, 14)),
    ("interpolate", RGBColor(44, 160, 44)),
    ("shade", RGBColor(148, 103, 189)),
    ("direct", RGBColor(188, 189, 34)),
];

fn draw_stage_breakdown<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, results: &BenchResults) -> Drawn {
    root.fill(&WHITE).map_err(err)?;
    let n = results.configs.len();
    let y_max = results.configs.iter().map(|r| r.frame_ms).fold(0.0f64, f64::max).max(1e-3) * 1.1;
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!("Stage times per configuration ({}, {})", results.adapter, results.timing.as_str()),
            (FAMILY, 18),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5f64..n as f64 - 0.5, 0.0..y_max)
        .map_err(err)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n.min(40))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 { format!("#{}", i as usize) } else { String::new() }
        })
        .x_desc("configuration (#i = row i of results.csv)")
        .y_desc("ms")
        .label_style((FAMILY, 13))
        .draw()
        .map_err(err)?;
    for (s, &(name, color)) in STAGES.iter().enumerate() {
        let bars: Vec<Rectangle<(f64, f64)>> = results
            .configs
            .iter()
            .enumerate()
            .filter_map(|(i, r)| {
                let ms = |k: usize| r.stages_ms.iter().find(|(n, _)| n == STAGES[k].0).map_or(0.0, |(_, ms)| *ms);
                let own = ms(s);
                (own > 0.0).then(|| {
                    let below: f64 = (0..s).map(ms).sum();
                    let x = i as f64;
                    Rectangle::new([(x - 0.35, below), (x + 0.35, below + own)], color.filled())
                })
            })
            .collect();
        if bars.is_empty() {
            continue;
        }
        chart
            .draw_series(bars)
            .map_err(err)?
            .label(name)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled()));
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight)
}

/// One scaling panel: configurations that differ only in the quantity on x, as lines.
struct Scaling {
    title: &'static str,
    x: fn(&ConfigResult) -> f64,
    /// Everything but the quantity on x, as a grouping key.
    rest: fn(&ConfigResult) -> String,
}

const SCALINGS: [Scaling; 3] = [
    Scaling {
        title: "VALs",
        x: |r| r.vals as f64,
        rest: |r| {
            let c = &r.config;
            format!(
                "{} {:?} {:?} {} {}x{}",
                r.variant, c.sparse_points_per_mesh, c.occlusion, c.glossy, c.width, c.height
            )
        },
    },
    Scaling {
        title: "sparse points",
        x: |r| r.sparse_points as f64,
        rest: |r| {
            let c = &r.config;
            format!("{} {} {:?} {} {}x{}", r.variant, c.rsm_resolution, c.occlusion, c.glossy, c.width, c.height)
        },
    },
    Scaling {
        title: "pixels",
        x: |r| r.pixels as f64,
        rest: |r| {
            let c = &r.config;
            format!("{} {:?} {} {:?} {}", r.variant, c.sparse_points_per_mesh, c.rsm_resolution, c.occlusion, c.glossy)
        },
    },
];

fn draw_scaling<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, results: &BenchResults) -> Drawn {
    root.fill(&WHITE).map_err(err)?;
    let panels = root.split_evenly((1, 3));
    for (panel, scaling) in panels.iter().zip(&SCALINGS) {
        // Lines of at least two distinct x values, sorted by x.
        let mut groups: Vec<(String, Vec<&ConfigResult>)> = Vec::new();
        for r in &results.configs {
            let key = (scaling.rest)(r);
            match groups.iter_mut().find(|(k, _)| *k == key) {
                Some((_, g)) => g.push(r),
                None => groups.push((key, vec![r])),
            }
        }
        groups.retain(|(_, g)| {
            let mut xs: Vec<f64> = g.iter().map(|r| (scaling.x)(r)).collect();
            xs.sort_by(f64::total_cmp);
            xs.dedup();
            xs.len() >= 2
        });
        let used: Vec<&ConfigResult> = groups.iter().flat_map(|(_, g)| g.iter().copied()).collect();
        let x_range = log_range(used.iter().map(|r| (scaling.x)(r)));
        let y_range = log_range(used.iter().flat_map(|r| [Some(r.sparse_indirect_ms), r.brute_force_ms]).flatten());
        let x_mid = (x_range.start * x_range.end).sqrt();
        let y_mid = (y_range.start * y_range.end).sqrt();
        let mut chart = ChartBuilder::on(panel)
            .caption(format!("time vs {} (log-log)", scaling.title), (FAMILY, 16))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x_range.log_scale(), y_range.log_scale())
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_labels(6)
            .y_labels(6)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.0}"))
            .x_desc(scaling.title)
            .y_desc(format!("ms ({})", results.timing.as_str()))
            .label_style((FAMILY, 12))
            .draw()
            .map_err(err)?;
        if groups.is_empty() {
            chart
                .draw_series([Text::new(format!("{} not swept", scaling.title), (x_mid, y_mid), (FAMILY, 14))])
                .map_err(err)?;
            continue;
        }
        for (g, (_, group)) in groups.iter_mut().enumerate() {
            group.sort_by(|a, b| (scaling.x)(a).total_cmp(&(scaling.x)(b)));
            let sparse: Vec<(f64, f64)> = group.iter().map(|r| ((scaling.x)(r), r.sparse_indirect_ms)).collect();
            let brute: Vec<(f64, f64)> =
                group.iter().filter_map(|r| Some(((scaling.x)(r), r.brute_force_ms?))).collect();
            let s = chart.draw_series(LineSeries::new(sparse.clone(), BLUE.stroke_width(2))).map_err(err)?;
            if g == 0 {
                s.label("sparse indirect")
                    .legend(|(x, y)| PathElement::new([(x, y), (x + 15, y)], BLUE.stroke_width(2)));
            }
            chart.draw_series(sparse.iter().map(|&p| Circle::new(p, 3, BLUE.filled()))).map_err(err)?;
            let b = chart.draw_series(LineSeries::new(brute.clone(), RED.stroke_width(2))).map_err(err)?;
            if g == 0 {
                b.label("brute force").legend(|(x, y)| PathElement::new([(x, y), (x + 15, y)], RED.stroke_width(2)));
            }
            chart.draw_series(brute.iter().map(|&p| Circle::new(p, 3, RED.filled()))).map_err(err)?;
        }
        draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_only_undominated_points() {
        let points = [(1.0, 0.5), (2.0, 0.6), (3.0, 0.2), (0.5, 0.9), (4.0, 0.2), (5.0, 0.1)];
        assert_eq!(pareto_front(&points), vec![3, 0, 2, 5]);
    }

    #[test]
    fn the_embedded_font_registers() {
        register_font().expect("DejaVu Sans parses");
    }
}

/// One configuration of the levels' plot: a level or a candidate one parameter from one.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelPoint {
    pub name: String,
    pub rel_rmse: f64,
    pub ms: f64,
    /// A level (labelled and drawn large) rather than a candidate.
    pub level: bool,
}

/// The levels' plot (`relume bench --levels`): error against exact over indirect time, the
/// levels and their candidates, the Pareto front of them all and the converging estimator's
/// curve `(ms, rel RMSE)`, into `<dir>/levels.png` and `.svg`.
pub fn write_levels(dir: &Path, title: &str, points: &[LevelPoint], curve: &[(f64, f64)]) -> Drawn {
    register_font()?;
    let data = (title, points, curve);
    png_and_svg!(dir, "levels", (900, 600), draw_levels, &data);
    Ok(())
}

fn draw_levels<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    (title, points, curve): &(&str, &[LevelPoint], &[(f64, f64)]),
) -> Drawn {
    root.fill(&WHITE).map_err(err)?;
    let xy: Vec<(f64, f64)> = points.iter().map(|p| (p.ms, p.rel_rmse)).collect();
    let y_max = xy.iter().map(|p| p.1).filter(|y| y.is_finite()).fold(0.0f64, f64::max).max(1e-3) * 1.15;
    let curve: Vec<(f64, f64)> =
        curve.iter().copied().filter(|p| p.0 > 0.0 && p.1.is_finite() && p.1 <= y_max).collect();
    let x_range = log_range(xy.iter().chain(&curve).map(|p| p.0));
    let mut chart = error_over_time(root, title, (x_range, y_max), "indirect ms (log)", "relative RMSE against exact")?;
    let candidates: Vec<(f64, f64)> = points.iter().filter(|p| !p.level).map(|p| (p.ms, p.rel_rmse)).collect();
    if !candidates.is_empty() {
        chart
            .draw_series(candidates.iter().map(|&p| Circle::new(p, 4, BLUE.mix(0.5).filled())))
            .map_err(err)?
            .label("one parameter from a level")
            .legend(|(x, y)| Circle::new((x + 5, y), 4, BLUE.mix(0.5).filled()));
    }
    let front: Vec<(f64, f64)> = pareto_front(&xy).into_iter().map(|i| xy[i]).collect();
    chart
        .draw_series(LineSeries::new(front, RED.stroke_width(2)))
        .map_err(err)?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 15, y)], RED.stroke_width(2)));
    let levels: Vec<&LevelPoint> = points.iter().filter(|p| p.level).collect();
    chart
        .draw_series(levels.iter().map(|p| TriangleMarker::new((p.ms, p.rel_rmse), 8, BLACK.filled())))
        .map_err(err)?
        .label("quality level")
        .legend(|(x, y)| TriangleMarker::new((x + 5, y), 8, BLACK.filled()));
    chart
        .draw_series(
            levels.iter().map(|p| {
                Text::new(format!("  {}", p.name), (p.ms, p.rel_rmse), (FAMILY, 14).into_font().color(&BLACK))
            }),
        )
        .map_err(err)?;
    if !curve.is_empty() {
        let green = RGBColor(44, 160, 44);
        chart
            .draw_series(LineSeries::new(curve.clone(), green.stroke_width(2)))
            .map_err(err)?
            .label("converging estimator (exact, N importance-sampled VALs; CPU)")
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 15, y)], green.stroke_width(2)));
        chart.draw_series(curve.iter().map(|&p| Cross::new(p, 4, green.stroke_width(2)))).map_err(err)?;
    }
    draw_legend(&mut chart, SeriesLabelPosition::UpperRight)
}
