//! Small SVG plots for reports (line plots over time, histograms): readable in any browser,
//! no plotting dependency.

use std::fmt::Write as _;

const W: f64 = 640.0;
const H: f64 = 360.0;
const LEFT: f64 = 64.0;
const RIGHT: f64 = 16.0;
const TOP: f64 = 36.0;
const BOTTOM: f64 = 48.0;

/// One line of a line plot.
pub struct Series<'a> {
    pub name: &'a str,
    pub colour: &'a str,
    pub points: &'a [(f64, f64)],
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// A "nice" tick step for a span (1, 2 or 5 times a power of ten, about five ticks).
fn tick_step(span: f64) -> f64 {
    if !(span.is_finite() && span > 0.0) {
        return 1.0;
    }
    let raw = span / 5.0;
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0].into_iter().map(|m| m * p).find(|s| *s >= raw).unwrap_or(10.0 * p)
}

struct Frame {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

impl Frame {
    fn px(&self, x: f64) -> f64 {
        LEFT + (x - self.x0) / (self.x1 - self.x0).max(1e-12) * (W - LEFT - RIGHT)
    }

    fn py(&self, y: f64) -> f64 {
        H - BOTTOM - (y - self.y0) / (self.y1 - self.y0).max(1e-12) * (H - TOP - BOTTOM)
    }

    /// Axes, ticks, labels and title.
    fn axes(&self, o: &mut String, title: &str, x_label: &str, y_label: &str) {
        let _ = write!(
            o,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" font-family="sans-serif" font-size="12"><rect width="100%" height="100%" fill="white"/><text x="{}" y="22" text-anchor="middle" font-size="14">{}</text>"#,
            W / 2.0,
            escape(title)
        );
        let _ = write!(
            o,
            r#"<line x1="{LEFT}" y1="{}" x2="{}" y2="{}" stroke="black"/><line x1="{LEFT}" y1="{TOP}" x2="{LEFT}" y2="{}" stroke="black"/>"#,
            H - BOTTOM,
            W - RIGHT,
            H - BOTTOM,
            H - BOTTOM
        );
        for (lo, hi, vertical) in [(self.x0, self.x1, false), (self.y0, self.y1, true)] {
            let step = tick_step(hi - lo);
            let mut v = (lo / step).ceil() * step;
            let mut n = 0;
            while v <= hi + step * 1e-9 && n < 50 {
                let label = if step >= 1.0 { format!("{v:.0}") } else { format!("{v:.2}") };
                if vertical {
                    let y = self.py(v);
                    let _ = write!(
                        o,
                        r##"<line x1="{LEFT}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{label}</text>"##,
                        W - RIGHT,
                        LEFT - 6.0,
                        y + 4.0
                    );
                } else {
                    let x = self.px(v);
                    let _ =
                        write!(o, r#"<text x="{x:.1}" y="{}" text-anchor="middle">{label}</text>"#, H - BOTTOM + 16.0);
                }
                v += step;
                n += 1;
            }
        }
        let _ = write!(
            o,
            r#"<text x="{}" y="{}" text-anchor="middle">{}</text><text x="16" y="{}" text-anchor="middle" transform="rotate(-90 16 {})">{}</text>"#,
            (LEFT + W - RIGHT) / 2.0,
            H - 10.0,
            escape(x_label),
            (TOP + H - BOTTOM) / 2.0,
            (TOP + H - BOTTOM) / 2.0,
            escape(y_label)
        );
    }
}

fn bounds(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .filter(|v| v.is_finite())
        .fold(None, |b, v| Some(b.map_or((v, v), |(lo, hi): (f64, f64)| (lo.min(v), hi.max(v)))))
}

/// Lines over a shared x axis; the y axis starts at 0. Series without points are listed but
/// not drawn; with no points at all the plot says so.
pub fn lines(title: &str, x_label: &str, y_label: &str, series: &[Series<'_>]) -> String {
    let all = || series.iter().flat_map(|s| s.points.iter());
    let (x0, x1) = bounds(all().map(|p| p.0)).unwrap_or((0.0, 1.0));
    let (_, y1) = bounds(all().map(|p| p.1)).unwrap_or((0.0, 1.0));
    let f = Frame { x0, x1: if x1 > x0 { x1 } else { x0 + 1.0 }, y0: 0.0, y1: if y1 > 0.0 { y1 * 1.05 } else { 1.0 } };
    let mut o = String::new();
    f.axes(&mut o, title, x_label, y_label);
    if all().next().is_none() {
        let _ = write!(o, r#"<text x="{}" y="{}" text-anchor="middle">no data</text>"#, W / 2.0, H / 2.0);
    }
    for (i, s) in series.iter().enumerate() {
        let path: Vec<String> = s
            .points
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .map(|p| format!("{:.1},{:.1}", f.px(p.0), f.py(p.1)))
            .collect();
        if !path.is_empty() {
            let _ = write!(
                o,
                r#"<polyline fill="none" stroke="{}" stroke-width="1.5" points="{}"/>"#,
                s.colour,
                path.join(" ")
            );
        }
        let y = TOP + 14.0 + 16.0 * i as f64;
        let _ = write!(
            o,
            r#"<rect x="{}" y="{}" width="12" height="3" fill="{}"/><text x="{}" y="{}">{}</text>"#,
            W - RIGHT - 150.0,
            y - 4.0,
            s.colour,
            W - RIGHT - 134.0,
            y,
            escape(s.name)
        );
    }
    o.push_str("</svg>\n");
    o
}

/// A histogram of `values` in `bins` equal bins from 0 to the largest value.
pub fn histogram(title: &str, x_label: &str, values: &[f64], bins: usize) -> String {
    let bins = bins.max(1);
    let (_, hi) = bounds(values.iter().copied()).unwrap_or((0.0, 1.0));
    let hi = if hi > 0.0 { hi } else { 1.0 };
    let mut counts = vec![0usize; bins];
    for v in values.iter().filter(|v| v.is_finite() && **v >= 0.0) {
        let i = ((v / hi) * bins as f64).floor() as usize;
        if let Some(c) = counts.get_mut(i.min(bins - 1)) {
            *c += 1;
        }
    }
    let top = counts.iter().copied().max().unwrap_or(0).max(1) as f64;
    let f = Frame { x0: 0.0, x1: hi, y0: 0.0, y1: top * 1.05 };
    let mut o = String::new();
    f.axes(&mut o, title, x_label, "count");
    let width = hi / bins as f64;
    for (i, c) in counts.iter().enumerate() {
        let (xa, xb) = (f.px(i as f64 * width), f.px((i + 1) as f64 * width));
        let y = f.py(*c as f64);
        let _ = write!(
            o,
            r##"<rect x="{xa:.1}" y="{y:.1}" width="{:.1}" height="{:.1}" fill="#c33"/>"##,
            (xb - xa - 1.0).max(0.5),
            (H - BOTTOM - y).max(0.0)
        );
    }
    o.push_str("</svg>\n");
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plots_are_svg_with_their_data() {
        let pts = [(0.0, 1.0), (1.0, 2.0), (2.0, 0.5)];
        let svg = lines("t <1>", "time (s)", "error (cm)", &[Series { name: "rig", colour: "red", points: &pts }]);
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("<polyline") && svg.contains("t &lt;1&gt;"));
        let empty = lines("none", "x", "y", &[Series { name: "rig", colour: "red", points: &[] }]);
        assert!(empty.contains("no data") && !empty.contains("<polyline"));
        let h = histogram("latency", "ms", &[1.0, 2.0, 2.5, f64::NAN, 10.0], 10);
        assert_eq!(h.matches("<rect x=").count(), 10);
        assert_eq!(tick_step(10.0), 2.0);
        assert_eq!(tick_step(0.3), 0.1);
    }
}
