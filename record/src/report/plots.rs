//! The report's plots, as SVG (text is left to the browser: no font files or fontconfig).

use crate::reader::Recording;
use crate::report::closed_loop::CaptureError;
use crate::report::summary::{pose_errors, secs, t0, tracking_errors};
use hitl_hal::DOF;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::ops::Range;
use std::path::Path;

type Res = Result<(), String>;

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// The legend box every plot draws: its series labels on a translucent white box.
fn draw_legend<'a, DB, CT>(chart: &mut ChartContext<'a, DB, CT>) -> Res
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate,
{
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)
}

/// The series colours of every plot (the report's joints, the campaign plots' targets).
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
];

/// An axis range covering the finite values with 5 % margins, never empty.
pub fn span(values: impl Iterator<Item = f64>) -> Range<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return 0.0..1.0;
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    if hi - lo < 1e-12 {
        return (lo - 1.0)..(hi + 1.0);
    }
    (lo - pad)..(hi + pad)
}

/// At most `max` points, evenly picked (SVG size stays bounded on long runs).
fn thin<T: Copy>(v: &[T], max: usize) -> Vec<T> {
    if v.len() <= max || max < 2 {
        return v.to_vec();
    }
    (0..max).map(|k| v[k * (v.len() - 1) / (max - 1)]).collect()
}

const MAX_POINTS: usize = 4000;

fn event_times(rec: &Recording) -> Vec<f64> {
    let t0 = t0(rec);
    rec.events.iter().map(|e| secs(e.t_ns, t0)).collect()
}

fn mark_events<DB: DrawingBackend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    events: &[f64],
    y: &Range<f64>,
) -> Res {
    if events.is_empty() {
        return Ok(());
    }
    chart
        .draw_series(
            events
                .iter()
                .map(|t| PathElement::new(vec![(*t, y.start), (*t, y.end)], RED.stroke_width(1))),
        )
        .map_err(err)?
        .label("safety event")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], RED));
    Ok(())
}

/// Setpoint (solid) and measured (dots) for each joint, one panel per joint.
pub fn joints(rec: &Recording, out: &Path) -> Res {
    let t0 = t0(rec);
    let root = SVGBackend::new(out, (1000, 1600)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let sp: Vec<(f64, [f64; DOF])> = thin(
        &rec.setpoints.iter().map(|s| (secs(s.t_ns, t0), s.q)).collect::<Vec<_>>(),
        MAX_POINTS,
    );
    let st: Vec<(f64, [f64; DOF])> =
        thin(&rec.states.iter().map(|s| (secs(s.t_ns, t0), s.q)).collect::<Vec<_>>(), MAX_POINTS);
    let xs = span(sp.iter().chain(st.iter()).map(|p| p.0));
    let events = event_times(rec);
    for (j, area) in root.split_evenly((7, 1)).iter().enumerate() {
        let ys = span(sp.iter().chain(st.iter()).map(|p| p.1[j].to_degrees()));
        let mut chart = ChartBuilder::on(area)
            .margin(6)
            .caption(format!("joint {} (deg)", j + 1), ("sans-serif", 14))
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(xs.clone(), ys.clone())
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("t (s)")
            .x_label_offset(0)
            .light_line_style(WHITE)
            .draw()
            .map_err(err)?;
        // The measured dots first, pale, and the setpoint line over them: where the arm follows
        // its setpoint the dots sit on the line and must not hide it.
        let measured = GREEN.mix(0.45);
        chart
            .draw_series(
                st.iter().map(|p| Circle::new((p.0, p.1[j].to_degrees()), 1, measured.filled())),
            )
            .map_err(err)?
            .label("measured")
            .legend(move |(x, y)| Circle::new((x + 7, y), 3, measured.filled()));
        chart
            .draw_series(LineSeries::new(
                sp.iter().map(|p| (p.0, p.1[j].to_degrees())),
                BLUE.stroke_width(2),
            ))
            .map_err(err)?
            .label("setpoint")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], BLUE.stroke_width(2)));
        mark_events(&mut chart, &events, &ys)?;
        draw_legend(&mut chart)?;
    }
    root.present().map_err(err)
}

/// Measured minus setpoint per joint, degrees.
pub fn tracking_error(rec: &Recording, out: &Path) -> Res {
    let e = thin(&tracking_errors(rec), MAX_POINTS);
    let root = SVGBackend::new(out, (1000, 450)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let xs = span(e.iter().map(|p| p.0));
    let ys = span(e.iter().flat_map(|p| p.1.iter().map(|v| v.to_degrees())));
    let mut chart = ChartBuilder::on(&root)
        .margin(10)
        .caption("tracking error: measured - setpoint (deg)", ("sans-serif", 18))
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(xs, ys.clone())
        .map_err(err)?;
    chart.configure_mesh().x_desc("t (s)").y_desc("deg").draw().map_err(err)?;
    for (j, c) in PALETTE.iter().enumerate() {
        chart
            .draw_series(LineSeries::new(
                e.iter().map(|p| (p.0, p.1[j].to_degrees())),
                c.stroke_width(1),
            ))
            .map_err(err)?
            .label(format!("j{}", j + 1))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], *c));
    }
    mark_events(&mut chart, &event_times(rec), &ys)?;
    draw_legend(&mut chart)?;
    root.present().map_err(err)
}

/// Histogram of the tick's wake-up lateness, microseconds.
pub fn lateness_histogram(rec: &Recording, out: &Path) -> Res {
    let v: Vec<f64> =
        rec.timing.iter().map(|t| t.wake_late_ns as f64 / 1e3).filter(|v| v.is_finite()).collect();
    let root = SVGBackend::new(out, (900, 450)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let r = span(v.iter().copied());
    const BINS: usize = 60;
    let w = (r.end - r.start) / BINS as f64;
    let mut counts = [0u64; BINS];
    for x in &v {
        let b = (((x - r.start) / w) as usize).min(BINS - 1);
        counts[b] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(0).max(1) as f64;
    let mut chart = ChartBuilder::on(&root)
        .margin(10)
        .caption(format!("tick wake-up lateness ({} ticks)", v.len()), ("sans-serif", 18))
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(r.clone(), 0.0..top * 1.05)
        .map_err(err)?;
    chart.configure_mesh().x_desc("late (us)").y_desc("ticks").draw().map_err(err)?;
    chart
        .draw_series(counts.iter().enumerate().map(|(i, c)| {
            let x0 = r.start + i as f64 * w;
            Rectangle::new([(x0, 0.0), (x0 + w, *c as f64)], BLUE.mix(0.7).filled())
        }))
        .map_err(err)?;
    root.present().map_err(err)
}

fn path_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    pts: &[[f64; 3]],
    (a, b): (usize, usize),
    title: &str,
) -> Res {
    let names = ["x", "y", "z"];
    let all = span(pts.iter().flat_map(|p| [p[a], p[b], 0.0]));
    let mut chart = ChartBuilder::on(area)
        .margin(10)
        .caption(title, ("sans-serif", 16))
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(all.clone(), all)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(format!("{} (m)", names[a]))
        .y_desc(format!("{} (m)", names[b]))
        .draw()
        .map_err(err)?;
    chart
        .draw_series(LineSeries::new(pts.iter().map(|p| (p[a], p[b])), BLUE))
        .map_err(err)?
        .label("camera")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], BLUE));
    if let Some(p) = pts.first() {
        chart
            .draw_series(std::iter::once(Circle::new((p[a], p[b]), 4, GREEN.filled())))
            .map_err(err)?
            .label("start")
            .legend(|(x, y)| Circle::new((x + 7, y), 3, GREEN.filled()));
    }
    chart
        .draw_series(std::iter::once(TriangleMarker::new((0.0, 0.0), 7, RED.filled())))
        .map_err(err)?
        .label("target")
        .legend(|(x, y)| TriangleMarker::new((x + 7, y), 4, RED.filled()));
    draw_legend(&mut chart)
}

/// The camera's position in the target frame (from `/tf`), two projections.
pub fn camera_path(rec: &Recording, out: &Path) -> Res {
    let pts: Vec<[f64; 3]> = thin(
        &rec.tf.iter().map(|t| t.camera_in_target().translation.vector.into()).collect::<Vec<_>>(),
        MAX_POINTS,
    );
    let root = SVGBackend::new(out, (1100, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let halves = root.split_evenly((1, 2));
    path_panel(&halves[0], &pts, (0, 1), "camera around the target: x-y")?;
    path_panel(&halves[1], &pts, (0, 2), "camera around the target: x-z")?;
    root.present().map_err(err)
}

/// The Sun phase schedule and the light level.
pub fn sun_phase(rec: &Recording, out: &Path) -> Res {
    let sun = rec.sun_phase().unwrap_or_default();
    let sun: Vec<(f64, f64)> =
        thin(&sun.0.iter().copied().zip(sun.1.iter().copied()).collect::<Vec<_>>(), MAX_POINTS);
    let t0 = t0(rec);
    let light: Vec<(f64, f64)> = thin(
        &rec.lights.iter().map(|l| (secs(l.t_ns, t0), f64::from(l.level))).collect::<Vec<_>>(),
        MAX_POINTS,
    );
    let root = SVGBackend::new(out, (1000, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let parts = root.split_evenly((2, 1));
    let xs = span(sun.iter().chain(light.iter()).map(|p| p.0));
    let mut c = ChartBuilder::on(&parts[0])
        .margin(10)
        .caption("Sun phase angle (trajectory time)", ("sans-serif", 16))
        .x_label_area_size(30)
        .y_label_area_size(55)
        .build_cartesian_2d(xs.clone(), 0.0..360.0)
        .map_err(err)?;
    c.configure_mesh().x_desc("t (s)").y_desc("deg").draw().map_err(err)?;
    c.draw_series(LineSeries::new(sun.iter().copied(), RGBColor(230, 150, 0))).map_err(err)?;
    let mut c = ChartBuilder::on(&parts[1])
        .margin(10)
        .caption("light level (/light/state)", ("sans-serif", 16))
        .x_label_area_size(30)
        .y_label_area_size(55)
        .build_cartesian_2d(xs, 0.0..1.05)
        .map_err(err)?;
    c.configure_mesh().x_desc("t (s)").draw().map_err(err)?;
    c.draw_series(LineSeries::new(light.iter().copied(), BLACK)).map_err(err)?;
    root.present().map_err(err)
}

/// Estimate vs ground truth as recorded (no first-frame calibration): translation in lab
/// millimetres and rotation (deg).
pub fn pose_error(rec: &Recording, out: &Path) -> Res {
    let e = thin(&pose_errors(rec), MAX_POINTS);
    let root = SVGBackend::new(out, (1000, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let parts = root.split_evenly((2, 1));
    let xs = span(e.iter().map(|p| p.0));
    let events = event_times(rec);
    for (k, (title, unit)) in
        [("translation error as recorded", "lab mm"), ("rotation error as recorded", "deg")]
            .iter()
            .enumerate()
    {
        let vals: Vec<(f64, f64)> =
            e.iter().map(|p| (p.0, if k == 0 { p.1 * 1e3 } else { p.2.to_degrees() })).collect();
        let ys = span(vals.iter().map(|p| p.1).chain([0.0]));
        let mut c = ChartBuilder::on(&parts[k])
            .margin(10)
            .caption(format!("pose {title} ({unit})"), ("sans-serif", 16))
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(xs.clone(), ys.clone())
            .map_err(err)?;
        c.configure_mesh().x_desc("t (s)").y_desc(*unit).draw().map_err(err)?;
        c.draw_series(LineSeries::new(vals.iter().copied(), BLUE)).map_err(err)?;
        c.draw_series(vals.iter().map(|p| Circle::new(*p, 2, BLUE.filled()))).map_err(err)?;
        mark_events(&mut c, &events, &ys)?;
    }
    root.present().map_err(err)
}

/// The paper's per-frame errors over the run (`hitl eval`'s, after the first-frame calibration):
/// e_t in real metres, and e_r with its symmetry-aware counterpart in degrees. `per_frame` is
/// the report's `pose_metrics.per_frame` (objects with `t_ns`, `et_m`, `er_deg`, `et_sym_m`,
/// `er_sym_deg`); frames with no estimate are not in it.
pub fn paper_error(rec: &Recording, per_frame: &[serde_json::Value], out: &Path) -> Res {
    let t0 = t0(rec);
    let g = |v: &serde_json::Value, k: &str| v.get(k).and_then(serde_json::Value::as_f64);
    let rows: Vec<(f64, [f64; 4])> = per_frame
        .iter()
        .filter_map(|v| {
            let t = v.get("t_ns").and_then(serde_json::Value::as_u64)?;
            let e = [g(v, "et_m")?, g(v, "et_sym_m")?, g(v, "er_deg")?, g(v, "er_sym_deg")?];
            Some((secs(t, t0), e))
        })
        .collect();
    let rows = thin(&rows, MAX_POINTS);
    let root = SVGBackend::new(out, (1000, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let parts = root.split_evenly((2, 1));
    let xs = span(rows.iter().map(|p| p.0));
    let panels = [
        ("e_t, the paper's translation error (real m)", "m", 0),
        ("e_r, the paper's rotation error (deg)", "deg", 2),
    ];
    for (k, (title, unit, col)) in panels.iter().enumerate() {
        let ys = span(rows.iter().flat_map(|p| [p.1[*col], p.1[col + 1]]).chain([0.0]));
        let mut c = ChartBuilder::on(&parts[k])
            .margin(10)
            .caption(*title, ("sans-serif", 16))
            .x_label_area_size(40)
            .y_label_area_size(65)
            .build_cartesian_2d(xs.clone(), ys)
            .map_err(err)?;
        c.configure_mesh().x_desc("t (s)").y_desc(*unit).draw().map_err(err)?;
        let sym = RGBColor(230, 120, 0);
        c.draw_series(LineSeries::new(rows.iter().map(|p| (p.0, p.1[*col])), BLUE))
            .map_err(err)?
            .label("as the paper scores it")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], BLUE));
        c.draw_series(LineSeries::new(
            rows.iter().map(|p| (p.0, p.1[col + 1])),
            sym.stroke_width(2),
        ))
        .map_err(err)?
        .label("up to the target's symmetry")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], sym.stroke_width(2)));
        draw_legend(&mut c)?;
    }
    root.present().map_err(err)
}

/// `--closed-loop`: the relative-position error per capture as vision measured it, without the
/// correction (what open loop would have had) and with the correction in effect (closed loop),
/// lab millimetres (`crate::report::closed_loop`).
pub fn closed_loop_error(rec: &Recording, out: &Path) -> Res {
    let Some(e) = crate::report::closed_loop::closed_loop_error(rec) else {
        return Err("no closed-loop measurement in the recording".into());
    };
    let c = thin(&e.per_capture, MAX_POINTS);
    let root = SVGBackend::new(out, (1000, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let xs = span(c.iter().map(|p| p.t_s));
    let ys = span(c.iter().flat_map(|p| [p.open_mm, p.closed_mm]).chain([0.0]));
    let mut chart = ChartBuilder::on(&root)
        .margin(10)
        .caption("relative-position error as vision measured it (lab mm)", ("sans-serif", 16))
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(xs, ys.clone())
        .map_err(err)?;
    chart.configure_mesh().x_desc("t (s)").y_desc("lab mm").draw().map_err(err)?;
    let open = PALETTE[1];
    let closed = PALETTE[0];
    type Pick = fn(&CaptureError) -> f64;
    let series: [(&str, RGBColor, Pick); 2] = [
        ("open loop (without the correction)", open, |p| p.open_mm),
        ("closed loop (with the correction in effect)", closed, |p| p.closed_mm),
    ];
    for (label, colour, pick) in series {
        chart
            .draw_series(LineSeries::new(
                c.iter().map(|p| (p.t_s, pick(p))),
                colour.stroke_width(2),
            ))
            .map_err(err)?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 15, y)], colour.stroke_width(2))
            });
    }
    // Captures the filter did not use, as hollow marks on the closed-loop line.
    chart
        .draw_series(
            c.iter().filter(|p| !p.used).map(|p| Circle::new((p.t_s, p.closed_mm), 3, RED)),
        )
        .map_err(err)?;
    mark_events(&mut chart, &event_times(rec), &ys)?;
    draw_legend(&mut chart)?;
    root.present().map_err(err)
}
