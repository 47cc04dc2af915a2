//! The error-versus-runtime plot: PSNR and FLIP against time (log scale), one
//! colour and marker per method, the Pareto front, SVG and PNG.

use super::{other_input, pareto, register_font};
use crate::evaluate::Record;
use plotters::coord::Shift;
use plotters::element::{DynElement, IntoDynElement};
use plotters::prelude::*;
use std::path::Path;

/// Colour and marker of a method in the plot.
#[derive(Clone, Copy, PartialEq)]
enum Shape {
    Circle,
    Square,
    Triangle,
    TriangleDown,
    Diamond,
    Cross,
}

fn style_of(method: &str, peer_index: usize) -> (RGBColor, Shape) {
    match method {
        "flr" => (RGBColor(31, 119, 180), Shape::Circle),
        "flnr" => (RGBColor(148, 103, 189), Shape::Diamond),
        "bmfr" => (RGBColor(255, 127, 14), Shape::Square),
        "bmfr-temporal" => (RGBColor(140, 86, 75), Shape::Square),
        "walr" => (RGBColor(44, 160, 44), Shape::Triangle),
        "walr-temporal" => (RGBColor(23, 190, 207), Shape::TriangleDown),
        _ => ([RGBColor(214, 39, 40), RGBColor(227, 119, 194), RGBColor(127, 127, 127), RGBColor(0, 0, 0)][peer_index % 4], Shape::Cross),
    }
}

/// A marker centred on `at` (data or pixel coordinates), 5 px in radius.
fn marker<'a, DB: DrawingBackend + 'a, C: Clone + 'a>(at: C, shape: Shape, color: RGBColor, hollow: bool) -> DynElement<'a, DB, C> {
    let fill: ShapeStyle = if hollow { color.stroke_width(2) } else { color.filled() };
    let line: ShapeStyle = color.stroke_width(2);
    let poly = |p: Vec<(i32, i32)>| -> DynElement<'a, DB, C> {
        if hollow {
            let mut closed = p.clone();
            closed.push(p[0]);
            (EmptyElement::at(at.clone()) + PathElement::new(closed, line)).into_dyn()
        } else {
            (EmptyElement::at(at.clone()) + Polygon::new(p, fill)).into_dyn()
        }
    };
    match shape {
        Shape::Circle => (EmptyElement::at(at.clone()) + Circle::new((0, 0), 5, fill)).into_dyn(),
        Shape::Square => poly(vec![(-4, -4), (4, -4), (4, 4), (-4, 4)]),
        Shape::Triangle => poly(vec![(0, -6), (5, 4), (-5, 4)]),
        Shape::TriangleDown => poly(vec![(0, 6), (5, -4), (-5, -4)]),
        Shape::Diamond => poly(vec![(0, -6), (6, 0), (0, 6), (-6, 0)]),
        Shape::Cross => (EmptyElement::at(at.clone())
            + PathElement::new(vec![(-5, -5), (5, 5)], color.stroke_width(3))
            + PathElement::new(vec![(-5, 5), (5, -5)], color.stroke_width(3)))
        .into_dyn(),
    }
}

pub(super) fn err<E: std::fmt::Debug>(e: E) -> String {
    format!("plot: {e:?}")
}

/// Methods of the plotted rows in first-seen order, each with its colour and marker.
fn method_styles(rows: &[&Record]) -> Vec<(String, RGBColor, Shape)> {
    let mut out: Vec<(String, RGBColor, Shape)> = vec![];
    let mut peers = 0;
    for r in rows {
        if !out.iter().any(|(m, _, _)| *m == r.method) {
            let (c, s) = style_of(&r.method, peers);
            if s == Shape::Cross {
                peers += 1;
            }
            out.push((r.method.clone(), c, s));
        }
    }
    out
}

fn is_peer(method: &str) -> bool {
    !crate::methods::METHODS.contains(&method)
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, rows: &[&Record]) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let timed: Vec<&Record> = rows.iter().copied().filter(|r| r.ms > 0.0 && r.method != "noisy").collect();
    if timed.is_empty() {
        return root.present().map_err(err);
    }
    let (plots, legend) = root.split_vertically(root.dim_in_pixel().1 - 64);
    let panels = plots.split_evenly((1, 2));
    let styles = method_styles(&timed);
    let (tmin, tmax) = timed.iter().fold((f64::MAX, 0f64), |a, r| (a.0.min(r.ms), a.1.max(r.ms)));
    let (tmin, tmax) = (tmin / 1.5, tmax * 1.5);
    let noisy: Option<&Record> = rows.iter().copied().find(|r| r.method == "noisy" && r.config == "noisy");
    for (k, panel) in panels.iter().enumerate() {
        let metric = |r: &Record| if k == 0 { r.psnr } else { r.flip };
        // the methods fill the y axis; the noisy input is named in the caption
        let (lo, hi) = timed.iter().fold((f64::MAX, f64::MIN), |a, r| (a.0.min(metric(r)), a.1.max(metric(r))));
        let pad = (hi - lo).max(1e-3) * 0.08;
        let name = if k == 0 { "PSNR (dB, higher is better)" } else { "FLIP (lower is better)" };
        let caption = match noisy {
            Some(n) if k == 0 => format!("PSNR vs time (noisy input: {:.2} dB, below the axis)", n.psnr),
            Some(n) => format!("FLIP vs time (noisy input: {:.3}, above the axis)", n.flip),
            None => format!("{} vs time", if k == 0 { "PSNR" } else { "FLIP" }),
        };
        let mut chart = ChartBuilder::on(panel)
            .caption(caption, ("sans-serif", 17))
            .margin(12)
            .x_label_area_size(38)
            .y_label_area_size(56)
            .build_cartesian_2d((tmin..tmax).log_scale(), (lo - pad)..(hi + pad))
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("ms per frame (log scale)")
            .y_desc(name)
            .label_style(("sans-serif", 12))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(err)?;
        let better = |a: &Record, b: &Record| if k == 0 { a.psnr > b.psnr } else { a.flip < b.flip };
        // the front of the configurations on the 1-spp frame (another input is another problem)
        let same: Vec<&Record> = timed.iter().copied().filter(|r| !other_input(r)).collect();
        let front: Vec<&Record> = pareto(&same, better).into_iter().map(|i| same[i]).collect();
        let mut pts: Vec<(f64, f64)> = front.iter().map(|r| (r.ms, metric(r))).collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        // a staircase: each front point holds until the next, faster-and-worse one
        let mut stairs = vec![];
        for (i, p) in pts.iter().enumerate() {
            if i > 0 {
                stairs.push((p.0, pts[i - 1].1));
            }
            stairs.push(*p);
        }
        chart.draw_series(LineSeries::new(stairs, RGBColor(90, 90, 90).stroke_width(1))).map_err(err)?;
        let area = chart.plotting_area();
        for (m, color, shape) in &styles {
            for r in timed.iter().filter(|r| &r.method == m) {
                area.draw(&marker((r.ms, metric(r)), *shape, *color, other_input(r))).map_err(err)?;
            }
        }
        // names: the Pareto-optimal configurations and every peer, each where
        // it overlaps no other name and no marker (farther off with a leader line)
        let mut taken: Vec<(i32, i32, i32, i32)> = timed
            .iter()
            .map(|r| {
                let (x, y) = chart.backend_coord(&(r.ms, metric(r)));
                (x - 6, y - 6, x + 6, y + 6)
            })
            .collect();
        let style = ("sans-serif", 11).into_font().color(&RGBColor(40, 40, 40));
        for r in timed.iter().filter(|r| front.iter().any(|f| std::ptr::eq(*f, **r)) || is_peer(&r.method)) {
            let (x, y) = chart.backend_coord(&(r.ms, metric(r)));
            let (tw, th) = (6 * r.config.chars().count() as i32 + 4, 13);
            let overlaps = |b: &(i32, i32, i32, i32), a: &(i32, i32, i32, i32)| a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3;
            let spots =
                [(8, -16), (8, 3), (-8 - tw, -16), (-8 - tw, 3), (8, -34), (8, 21), (-8 - tw, -34), (-8 - tw, 21), (8, -52), (8, 39)];
            let inside = |b: &(i32, i32, i32, i32)| {
                let ((x0, y0), (x1, y1)) = (
                    panel.get_base_pixel(),
                    (panel.get_base_pixel().0 + panel.dim_in_pixel().0 as i32, panel.get_base_pixel().1 + panel.dim_in_pixel().1 as i32),
                );
                b.0 >= x0 && b.2 <= x1 && b.1 >= y0 + 30 && b.3 <= y1
            };
            let spot = spots
                .iter()
                .map(|(dx, dy)| (x + dx, y + dy, x + dx + tw, y + dy + th))
                .find(|b| inside(b) && !taken.iter().any(|t| overlaps(t, b)))
                .unwrap_or((x + 8, y - 16, x + 8 + tw, y - 3));
            if (spot.1 - y).abs() > 20 {
                let ly = if spot.1 < y { spot.3 } else { spot.1 };
                root.draw(&PathElement::new(vec![(x, y), (spot.0 + 2, ly)], RGBColor(150, 150, 150))).map_err(err)?;
            }
            root.draw(&Text::new(r.config.clone(), (spot.0 + 2, spot.1), style.clone())).map_err(err)?;
            taken.push(spot);
        }
    }
    // the legend, under both panels
    legend.fill(&WHITE).map_err(err)?;
    let font = ("sans-serif", 13).into_font();
    let (mut x, y0, y1) = (70i32, 18i32, 44i32);
    for (m, color, shape) in &styles {
        let text = if is_peer(m) { format!("{m} (peer)") } else { m.clone() };
        legend.draw(&marker((x, y0), *shape, *color, false)).map_err(err)?;
        legend.draw(&Text::new(text.clone(), (x + 10, y0 - 7), font.clone())).map_err(err)?;
        x += 30 + 8 * text.chars().count() as i32;
    }
    let grey = RGBColor(90, 90, 90);
    legend.draw(&PathElement::new(vec![(70, y1 - 4), (80, y1 - 4), (80, y1 + 4), (90, y1 + 4)], grey.stroke_width(1))).map_err(err)?;
    let front = "Pareto front of the 1-spp configurations (none is both faster and better; named)";
    legend.draw(&Text::new(front, (100, y1 - 7), font.clone())).map_err(err)?;
    let x = 130 + 6 * front.chars().count() as i32;
    legend.draw(&marker((x, y1), Shape::Circle, grey, true)).map_err(err)?;
    let hollow = "hollow: another input, 4 spp (noisy4) or traced at reduced resolution and upsampled (upN)";
    legend.draw(&Text::new(hollow, (x + 14, y1 - 7), font.clone())).map_err(err)?;
    root.present().map_err(err)
}

/// Writes `plot.svg` and `plot.png` into `dir`.
pub fn plot(dir: &Path, rows: &[&Record]) -> Result<(), String> {
    register_font();
    let size = (1400, 620);
    let svg = dir.join("plot.svg");
    draw(SVGBackend::new(&svg, size).into_drawing_area(), rows)?;
    let png = dir.join("plot.png");
    draw(BitMapBackend::new(&png, size).into_drawing_area(), rows)?;
    Ok(())
}
