//! A small SVG line-plot writer (axes, linear or log scales, legend), so the harness needs
//! no plotting crate. Pure: `tests/harness_pure.rs` includes this file by path.

use std::fmt::Write;

/// One line of a plot.
#[derive(Debug, Clone)]
pub struct Series {
    pub label: String,
    /// (x, y); points that a log axis cannot show (<= 0, not finite) are left out.
    pub points: Vec<(f64, f64)>,
    pub dashed: bool,
}

#[derive(Debug, Clone)]
pub struct Plot {
    pub title: String,
    /// A second, smaller line under the title (what was measured, where).
    pub subtitle: String,
    pub x_label: String,
    pub y_label: String,
    pub log_x: bool,
    pub log_y: bool,
    pub series: Vec<Series>,
}

const WIDTH: f64 = 720.0;
const HEIGHT: f64 = 480.0;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 52.0;
const BOTTOM: f64 = 60.0;
/// Colour-blind-safe (Okabe-Ito).
const COLOURS: [&str; 7] = ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000"];

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// One axis: data range, scale, and the map to pixels.
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
}

impl Axis {
    /// `headroom`: a fraction of the data's range added above it (room for the legend).
    fn new(values: impl Iterator<Item = f64>, log: bool, headroom: f64) -> Axis {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values {
            let v = if log { v.log10() } else { v };
            lo = lo.min(v);
            hi = hi.max(v);
        }
        if !lo.is_finite() {
            (lo, hi) = (0.0, 1.0);
        }
        let base = if log { lo } else { lo.min(0.0) };
        hi += headroom * (hi - base);
        if log {
            // Out to the nearest 1, 2 or 5 times a power of ten, so that both ends have a tick.
            let down = |v: f64| {
                let d = v.floor();
                [5.0f64, 2.0, 1.0].iter().map(|m| d + m.log10()).find(|t| *t <= v + 1e-12).unwrap_or(d)
            };
            let up = |v: f64| {
                let d = v.floor();
                [1.0f64, 2.0, 5.0, 10.0].iter().map(|m| d + m.log10()).find(|t| *t >= v - 1e-12).unwrap_or(d + 1.0)
            };
            (lo, hi) = (down(lo), up(hi));
            if hi <= lo {
                (lo, hi) = (down(lo - 0.1), up(hi + 0.1));
            }
        } else {
            if hi <= lo {
                (lo, hi) = (lo - 0.5 * lo.abs().max(1.0), hi + 0.5 * hi.abs().max(1.0));
            }
            // Linear axes start at zero when the data is all positive: costs compare to 0.
            if lo > 0.0 {
                lo = 0.0;
            }
            let step = nice_step((hi - lo) / 5.0);
            (lo, hi) = ((lo / step).floor() * step, (hi / step).ceil() * step);
        }
        Axis { lo, hi, log }
    }

    /// Position in [0, 1] of a data value.
    fn unit(&self, v: f64) -> f64 {
        let v = if self.log { v.log10() } else { v };
        (v - self.lo) / (self.hi - self.lo)
    }

    /// (data value, label, major) of the ticks.
    fn ticks(&self) -> Vec<(f64, String, bool)> {
        let mut out = Vec::new();
        if self.log {
            // Decades are major ticks; 2 and 5 minor ones, labelled when there are few decades.
            let few = self.hi - self.lo <= 2.5;
            for d in self.lo.floor() as i32..=self.hi.ceil() as i32 {
                for m in [1.0, 2.0, 5.0] {
                    let v = m * 10f64.powi(d);
                    let l = v.log10();
                    if l < self.lo - 1e-9 || l > self.hi + 1e-9 {
                        continue;
                    }
                    let major = m == 1.0;
                    out.push((v, if major || few { format_number(v) } else { String::new() }, major));
                }
            }
        } else {
            let step = nice_step((self.hi - self.lo) / 5.0);
            let mut v = self.lo;
            while v <= self.hi + step * 1e-9 {
                out.push((v, format_number(v), true));
                v += step;
            }
        }
        out
    }
}

/// 1, 2 or 5 times a power of ten, at least `raw`.
fn nice_step(raw: f64) -> f64 {
    if !(raw > 0.0 && raw.is_finite()) {
        return 1.0;
    }
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * p).find(|s| *s >= raw * (1.0 - 1e-9)).unwrap_or(10.0 * p)
}

/// A short label: 0.001, 0.5, 20, 1000, 1e+06.
pub fn format_number(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-4..1e5).contains(&a) {
        return format!("{v:.0e}");
    }
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

fn visible(series: &Series, log_x: bool, log_y: bool) -> Vec<(f64, f64)> {
    let ok = |v: f64, log: bool| v.is_finite() && (!log || v > 0.0);
    series.points.iter().copied().filter(|&(x, y)| ok(x, log_x) && ok(y, log_y)).collect()
}

/// The plot as an SVG document.
pub fn render(plot: &Plot) -> String {
    let shown: Vec<Vec<(f64, f64)>> = plot.series.iter().map(|s| visible(s, plot.log_x, plot.log_y)).collect();
    let xa = Axis::new(shown.iter().flatten().map(|p| p.0), plot.log_x, 0.0);
    let ya = Axis::new(shown.iter().flatten().map(|p| p.1), plot.log_y, 0.3);
    let (pw, ph) = (WIDTH - LEFT - RIGHT, HEIGHT - TOP - BOTTOM);
    let px = |x: f64| LEFT + xa.unit(x) * pw;
    let py = |y: f64| TOP + (1.0 - ya.unit(y)) * ph;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" viewBox="0 0 {WIDTH} {HEIGHT}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{WIDTH}" height="{HEIGHT}" fill="white"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{}" y="20" text-anchor="middle" font-size="15">{}</text>"#,
        WIDTH / 2.0,
        escape(&plot.title)
    );
    let _ = writeln!(
        s,
        r##"<text x="{}" y="38" text-anchor="middle" font-size="11" fill="#444">{}</text>"##,
        WIDTH / 2.0,
        escape(&plot.subtitle)
    );
    for (v, label, major) in xa.ticks() {
        let x = px(v);
        if !(LEFT - 0.5..=LEFT + pw + 0.5).contains(&x) {
            continue;
        }
        let colour = if major { "#ccc" } else { "#eee" };
        let _ = writeln!(s, r#"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{:.1}" stroke="{colour}"/>"#, TOP + ph);
        if !label.is_empty() {
            let _ = writeln!(s, r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle">{label}</text>"#, TOP + ph + 16.0);
        }
    }
    for (v, label, major) in ya.ticks() {
        let y = py(v);
        if !(TOP - 0.5..=TOP + ph + 0.5).contains(&y) {
            continue;
        }
        let colour = if major { "#ccc" } else { "#eee" };
        let _ = writeln!(s, r#"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{colour}"/>"#, LEFT + pw);
        if !label.is_empty() {
            let _ = writeln!(s, r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{label}</text>"#, LEFT - 6.0, y + 4.0);
        }
    }
    let _ = writeln!(s, r#"<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="none" stroke="black"/>"#);
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
        LEFT + pw / 2.0,
        HEIGHT - 18.0,
        escape(&plot.x_label)
    );
    let _ = writeln!(
        s,
        r#"<text x="18" y="{:.1}" text-anchor="middle" transform="rotate(-90 18 {:.1})">{}</text>"#,
        TOP + ph / 2.0,
        TOP + ph / 2.0,
        escape(&plot.y_label)
    );
    for (i, (series, points)) in plot.series.iter().zip(&shown).enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let dash = if series.dashed { r#" stroke-dasharray="6 4""# } else { "" };
        let path: Vec<String> = points.iter().map(|&(x, y)| format!("{:.1},{:.1}", px(x), py(y))).collect();
        if path.len() > 1 {
            let _ = writeln!(
                s,
                r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="2"{dash}/>"#,
                path.join(" ")
            );
        }
        for &(x, y) in points {
            let _ = writeln!(s, r#"<circle cx="{:.1}" cy="{:.1}" r="3" fill="{colour}"/>"#, px(x), py(y));
        }
    }
    // The legend goes in the corner of the plot area that hides the least of the lines
    // (counted at points spaced along them), the top right on a tie.
    let rows = plot.series.len() as f64;
    let longest = plot.series.iter().map(|s| s.label.chars().count()).max().unwrap_or(0) as f64;
    let (lw, lh) = (longest * 6.8 + 44.0, rows * 18.0 + 8.0);
    let samples: Vec<(f64, f64)> = shown
        .iter()
        .flat_map(|points| {
            let pixels: Vec<(f64, f64)> = points.iter().map(|&(x, y)| (px(x), py(y))).collect();
            let mut out = pixels.clone();
            for w in pixels.windows(2) {
                out.extend((1..16).map(|k| {
                    let f = k as f64 / 16.0;
                    (w[0].0 + f * (w[1].0 - w[0].0), w[0].1 + f * (w[1].1 - w[0].1))
                }));
            }
            out
        })
        .collect();
    let corners = [
        (LEFT + pw - lw - 8.0, TOP + 8.0),
        (LEFT + 8.0, TOP + 8.0),
        (LEFT + pw - lw - 8.0, TOP + ph - lh - 8.0),
        (LEFT + 8.0, TOP + ph - lh - 8.0),
    ];
    let hidden = |&(x, y): &(f64, f64)| {
        samples.iter().filter(|(sx, sy)| (x..=x + lw).contains(sx) && (y..=y + lh).contains(sy)).count()
    };
    let (lx, ly) = corners.iter().copied().min_by_key(hidden).unwrap_or(corners[0]);
    if rows > 0.0 {
        let _ = writeln!(
            s,
            r##"<rect x="{lx:.1}" y="{ly:.1}" width="{lw:.1}" height="{lh:.1}" fill="white" fill-opacity="0.9" stroke="#999"/>"##
        );
    }
    for (i, series) in plot.series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let dash = if series.dashed { r#" stroke-dasharray="6 4""# } else { "" };
        let y = ly + 14.0 + 18.0 * i as f64;
        let _ = writeln!(
            s,
            r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{colour}" stroke-width="2"{dash}/>"#,
            lx + 6.0,
            y - 4.0,
            lx + 30.0,
            y - 4.0
        );
        let _ = writeln!(s, r#"<text x="{:.1}" y="{y:.1}">{}</text>"#, lx + 36.0, escape(&series.label));
    }
    s.push_str("</svg>\n");
    s
}
