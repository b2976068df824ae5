//! The paper's campaign plots as SVG (text left to the browser, as the report's plots): mean e_t
//! and mean e_r against a swept parameter, one series per target, error bars of one temporal
//! standard deviation, and the ground-truth-mesh baseline of the same recordings dotted.
//!
//! - `range.svg` when `range_m` varies (the paper's RQ3 figure);
//! - `sun-phase.svg` when `sun_phase_deg` varies (x: the window's middle phase; RQ4), or else
//!   when `arc_deg` varies (x: the interval's middle argument of latitude; results.csv gives each
//!   interval's planned Sun phase range);
//! - `mesh-faces.svg` when `mesh_faces` varies (RQ2).
//!
//! Cases that share a target and an x value (other parameters varied too) are averaged. The
//! baseline is drawn where it differs from the estimator (a decimated mesh); range and face count
//! axes place their values evenly, in order.

use super::collect::Row;
use super::manifest::parse_window;
use hitl_record::report::plots::{span, PALETTE};
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

type Res<T> = Result<T, String>;

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// One point of a series: x, mean, std (estimator) and baseline mean.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub x: f64,
    pub mean: f64,
    pub std: f64,
    pub baseline: Option<f64>,
}

/// Sums of mean, std and baseline mean, and the counts behind them (cases, cases with a baseline).
type Sums = (f64, f64, f64, usize, usize);

/// The series of one metric: target -> points sorted by x. `x_of` maps a row to its x (None:
/// not plotted), `scale` converts the metric's unit.
pub fn series(
    rows: &[Row],
    x_of: &dyn Fn(&Row) -> Option<f64>,
    mean_key: &str,
    std_key: &str,
) -> BTreeMap<String, Vec<Point>> {
    // (target, x bits) -> sums
    let mut acc: BTreeMap<(String, u64), Sums> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.status == "ok") {
        let (Some(x), Some(m)) = (x_of(r), r.metric(mean_key)) else { continue };
        let s = r.metric(std_key).unwrap_or(0.0);
        let e = acc.entry((r.param_text("target"), x.to_bits())).or_insert((0.0, 0.0, 0.0, 0, 0));
        e.0 += m;
        e.1 += s;
        e.3 += 1;
        if let Some(b) = r.baseline_metric(mean_key) {
            e.2 += b;
            e.4 += 1;
        }
    }
    let mut out: BTreeMap<String, Vec<Point>> = BTreeMap::new();
    for ((target, xb), (m, s, b, n, nb)) in acc {
        out.entry(target).or_default().push(Point {
            x: f64::from_bits(xb),
            mean: m / n as f64,
            std: s / n as f64,
            baseline: (nb > 0).then(|| b / nb as f64),
        });
    }
    for pts in out.values_mut() {
        pts.sort_by(|a, b| a.x.total_cmp(&b.x));
    }
    out
}

/// A number as a short axis label.
fn label(x: f64) -> String {
    if x.abs() >= 100.0 {
        format!("{x:.0}")
    } else {
        format!("{x:.2}").trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Two panels (e_t, e_r) of one sweep. `categorical`: the distinct x values are placed evenly, in
/// order, and labelled with their values (ranges, face counts); otherwise x is a linear axis.
fn sweep(
    rows: &[Row],
    x_of: &dyn Fn(&Row) -> Option<f64>,
    x_desc: &str,
    categorical: bool,
    out: &Path,
) -> Res<bool> {
    let mut values: Vec<f64> = rows.iter().filter(|r| r.status == "ok").filter_map(x_of).collect();
    values.sort_by(f64::total_cmp);
    values.dedup();
    let tx = |x: f64| {
        if categorical {
            values.iter().position(|v| *v == x).map_or(x, |i| i as f64)
        } else {
            x
        }
    };
    let panels = [
        ("mean_et_m", "std_et_m", "translation error e_t", "m"),
        ("mean_er_deg", "std_er_deg", "rotation error e_r", "deg"),
    ];
    let all: Vec<BTreeMap<String, Vec<Point>>> =
        panels.iter().map(|(m, s, _, _)| series(rows, x_of, m, s)).collect();
    if all[0].values().all(|p| p.is_empty()) {
        return Ok(false);
    }
    let root = SVGBackend::new(out, (1100, 450)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let parts = root.split_evenly((1, 2));
    for (k, (_, _, title, unit)) in panels.iter().enumerate() {
        let data = &all[k];
        let xs = if categorical {
            -0.5..(values.len() as f64 - 0.5)
        } else {
            span(data.values().flatten().map(|p| tx(p.x)))
        };
        let ys = span(
            data.values()
                .flatten()
                .flat_map(|p| {
                    [p.mean + p.std, (p.mean - p.std).max(0.0), p.baseline.unwrap_or(p.mean)]
                })
                .chain([0.0]),
        );
        let mut c = ChartBuilder::on(&parts[k])
            .margin(12)
            .caption(format!("{title} ({unit})"), ("sans-serif", 16))
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(xs, ys)
            .map_err(err)?;
        let fmt_x = |v: &f64| {
            if !categorical {
                return label(*v);
            }
            let i = v.round();
            match values.get(i as usize) {
                Some(x) if (v - i).abs() < 1e-6 && i >= 0.0 => label(*x),
                _ => String::new(),
            }
        };
        let ticks = if categorical { values.len() } else { 10 };
        c.configure_mesh()
            .x_labels(ticks)
            .disable_x_mesh()
            .x_desc(x_desc)
            .y_desc(*unit)
            .x_label_formatter(&fmt_x)
            .draw()
            .map_err(err)?;
        for (i, (target, pts)) in data.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let line: Vec<(f64, f64)> = pts.iter().map(|p| (tx(p.x), p.mean)).collect();
            c.draw_series(LineSeries::new(line.clone(), color.stroke_width(2)))
                .map_err(err)?
                .label(target.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                });
            c.draw_series(pts.iter().map(|p| {
                ErrorBar::new_vertical(
                    tx(p.x),
                    (p.mean - p.std).max(0.0),
                    p.mean,
                    p.mean + p.std,
                    color,
                    8,
                )
            }))
            .map_err(err)?;
            c.draw_series(line.iter().map(|p| Circle::new(*p, 3, color.filled()))).map_err(err)?;
            let base: Vec<(f64, f64)> =
                pts.iter().filter_map(|p| p.baseline.map(|b| (tx(p.x), b))).collect();
            // Drawn where it differs from the estimator (a decimated mesh); else it is the line.
            let differs =
                pts.iter().any(|p| p.baseline.is_some_and(|b| (b - p.mean).abs() > 1e-12));
            if differs {
                c.draw_series(DashedLineSeries::new(base, 3, 4, color.stroke_width(1)))
                    .map_err(err)?
                    .label(format!("{target}, ground-truth mesh"))
                    .legend(move |(x, y)| {
                        PathElement::new(
                            vec![(x, y), (x + 4, y), (x + 8, y)],
                            color.stroke_width(1),
                        )
                    });
            }
        }
        c.configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK.mix(0.3))
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(true)
}

/// The middle of a phase window, degrees in [0, 360) (a window through 0 wraps).
pub fn window_middle(text: &str) -> Option<f64> {
    let (a, b) = parse_window(text)?;
    let b = if b < a { b + 360.0 } else { b };
    Some(((a + b) / 2.0).rem_euclid(360.0))
}

/// Write every plot the rows' varied parameters call for; returns the files written.
pub fn write_all(rows: &[Row], dir: &Path) -> Res<Vec<PathBuf>> {
    let varied = rows.first().map(|r| r.varied.clone()).unwrap_or_default();
    let mut written = Vec::new();
    let has = |k: &str| varied.iter().any(|v| v == k);
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut plot =
        |name: &str, x_of: &dyn Fn(&Row) -> Option<f64>, desc: &str, log: bool| -> Res<()> {
            let path = dir.join(name);
            if sweep(rows, x_of, desc, log, &path)? {
                written.push(path);
            }
            Ok(())
        };
    if has("range_m") {
        plot("range.svg", &|r| r.param("range_m").and_then(|v| v.as_f64()), "range (m)", true)?;
    }
    if has("sun_phase_deg") {
        plot(
            "sun-phase.svg",
            &|r| window_middle(&r.param_text("sun_phase_deg")),
            "oriented Sun phase, middle of the window (deg)",
            false,
        )?;
    } else if has("arc_deg") {
        plot(
            "sun-phase.svg",
            &|r| parse_window(&r.param_text("arc_deg")).map(|(a, b)| (a + b) / 2.0),
            "argument of latitude u, middle of the interval (deg)",
            false,
        )?;
    }
    if has("mesh_faces") {
        plot(
            "mesh-faces.svg",
            &|r| r.param("mesh_faces").and_then(|v| v.as_f64()),
            "estimator mesh faces",
            true,
        )?;
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_middles_wrap() {
        let near = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 1e-9);
        assert!(near(window_middle("356:23.8"), 9.9));
        assert!(near(window_middle("211.6:257.7"), 234.65));
        assert_eq!(window_middle("x"), None);
    }
}
