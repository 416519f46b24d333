//! Report helpers for the ablation harness: Markdown tables, number
//! formatting, a hand-rolled SVG line chart and a description of the
//! machine. No dependencies; the harness regenerates every figure.

use std::fmt::Write as _;

/// A Markdown table; `right` marks right-aligned (numeric) columns.
pub fn table(headers: &[&str], right: &[bool], rows: &[Vec<String>]) -> String {
    let mut s = String::new();
    s.push('|');
    for h in headers {
        let _ = write!(s, " {h} |");
    }
    s.push_str("\n|");
    for i in 0..headers.len() {
        s.push_str(if right.get(i).copied().unwrap_or(false) { " ---: |" } else { " --- |" });
    }
    s.push('\n');
    for r in rows {
        s.push('|');
        for c in r {
            let _ = write!(s, " {c} |");
        }
        s.push('\n');
    }
    s
}

/// Bytes as MiB with two decimals (the paper's tables use MB).
pub fn mib(bytes: f64) -> String {
    format!("{:.2}", bytes / (1024.0 * 1024.0))
}

/// A count with thousands separators.
pub fn count(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// Seconds as a readable duration.
pub fn secs(s: f64) -> String {
    if s >= 1.0 {
        format!("{s:.2} s")
    } else if s >= 1e-3 {
        format!("{:.1} ms", s * 1e3)
    } else {
        format!("{:.1} µs", s * 1e6)
    }
}

/// Nanoseconds per item.
pub fn ns_per(total_s: f64, items: usize) -> String {
    if items == 0 {
        return "–".into();
    }
    format!("{:.0}", total_s * 1e9 / items as f64)
}

/// One line of a [`Chart`].
#[derive(Clone, Debug, Default)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// Dashed line (for formulas next to measurements).
    pub dashed: bool,
}

/// A line chart rendered as standalone SVG.
#[derive(Clone, Debug, Default)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_x: bool,
    pub log_y: bool,
    pub series: Vec<Series>,
}

const PALETTE: [&str; 10] =
    ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#17becf", "#bcbd22"];

/// Readable tick positions over `[lo, hi]`.
fn linear_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return vec![lo];
    }
    let raw = (hi - lo) / 6.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0].iter().map(|m| m * mag).find(|s| *s >= raw).unwrap_or(10.0 * mag);
    let mut t = (lo / step).ceil() * step;
    let mut v = Vec::new();
    while t <= hi + step * 1e-9 {
        v.push(t);
        t += step;
    }
    v
}

fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let (a, b) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let mut v = Vec::new();
    for e in a..=b {
        for m in [1.0, 2.0, 5.0] {
            let t = m * 10f64.powi(e);
            if t >= lo * 0.999 && t <= hi * 1.001 {
                v.push(t);
            }
        }
    }
    if v.len() > 12 {
        v.retain(|t| (t.log10() - t.log10().round()).abs() < 1e-9);
    }
    v
}

fn tick_label(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-2..1e4).contains(&a) {
        let e = a.log10().floor() as i32;
        let m = v / 10f64.powi(e);
        if (m - m.round()).abs() < 1e-9 {
            format!("{}e{e}", m.round())
        } else {
            format!("{m:.1}e{e}")
        }
    } else if (v - v.round()).abs() < 1e-9 {
        format!("{}", v.round())
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

impl Chart {
    /// The chart as an SVG document (880 × 480).
    pub fn to_svg(&self) -> String {
        let (w, h) = (880.0, 480.0);
        let (left, right, top, bottom) = (80.0, 250.0, 40.0, 60.0);
        let (pw, ph) = (w - left - right, h - top - bottom);
        let pts =
            self.series.iter().flat_map(|s| s.points.iter()).filter(|p| {
                p.0.is_finite() && p.1.is_finite() && (!self.log_x || p.0 > 0.0) && (!self.log_y || p.1 > 0.0)
            });
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in pts {
            x0 = x0.min(p.0);
            x1 = x1.max(p.0);
            y0 = y0.min(p.1);
            y1 = y1.max(p.1);
        }
        if x0 > x1 {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if !self.log_y {
            y0 = y0.min(0.0);
        }
        let tf = |v: f64, log: bool| if log { v.log10() } else { v };
        let (mut tx0, mut tx1) = (tf(x0, self.log_x), tf(x1, self.log_x));
        let (mut ty0, mut ty1) = (tf(y0, self.log_y), tf(y1, self.log_y));
        if tx1 - tx0 < 1e-12 {
            tx0 -= 0.5;
            tx1 += 0.5;
        }
        if ty1 - ty0 < 1e-12 {
            ty0 -= 0.5;
            ty1 += 0.5;
        }
        if self.log_y {
            ty0 -= 0.05 * (ty1 - ty0);
            ty1 += 0.05 * (ty1 - ty0);
        } else {
            ty1 += 0.05 * (ty1 - ty0);
        }
        if self.log_x {
            let pad = 0.04 * (tx1 - tx0);
            tx0 -= pad;
            tx1 += pad;
        }
        let sx = |v: f64| left + (tf(v, self.log_x) - tx0) / (tx1 - tx0) * pw;
        let sy = |v: f64| top + ph - (tf(v, self.log_y) - ty0) / (ty1 - ty0) * ph;

        let mut s = String::new();
        let _ = writeln!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#
        );
        let _ = writeln!(s, r#"<rect width="{w}" height="{h}" fill="white"/>"#);
        let _ = writeln!(
            s,
            r#"<text x="{}" y="22" text-anchor="middle" font-size="15">{}</text>"#,
            left + pw / 2.0,
            esc(&self.title)
        );
        // grid and ticks
        let (xl, xh) = if self.log_x { (10f64.powf(tx0), 10f64.powf(tx1)) } else { (tx0, tx1) };
        let (yl, yh) = if self.log_y { (10f64.powf(ty0), 10f64.powf(ty1)) } else { (ty0, ty1) };
        let xt = if self.log_x { log_ticks(xl, xh) } else { linear_ticks(xl, xh) };
        let yt = if self.log_y { log_ticks(yl, yh) } else { linear_ticks(yl, yh) };
        for t in &xt {
            let x = sx(*t);
            let _ = writeln!(s, r##"<line x1="{x:.1}" y1="{top}" x2="{x:.1}" y2="{}" stroke="#e5e5e5"/>"##, top + ph);
            let _ = writeln!(
                s,
                r#"<text x="{x:.1}" y="{}" text-anchor="middle">{}</text>"#,
                top + ph + 16.0,
                tick_label(*t)
            );
        }
        for t in &yt {
            let y = sy(*t);
            let _ = writeln!(s, r##"<line x1="{left}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#e5e5e5"/>"##, left + pw);
            let _ = writeln!(
                s,
                r#"<text x="{}" y="{:.1}" text-anchor="end">{}</text>"#,
                left - 6.0,
                y + 4.0,
                tick_label(*t)
            );
        }
        let _ = writeln!(s, r#"<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="black"/>"#);
        let _ = writeln!(
            s,
            r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
            left + pw / 2.0,
            h - 18.0,
            esc(&self.x_label)
        );
        let _ = writeln!(
            s,
            r#"<text transform="translate(18 {}) rotate(-90)" text-anchor="middle">{}</text>"#,
            top + ph / 2.0,
            esc(&self.y_label)
        );
        // series
        for (i, ser) in self.series.iter().enumerate() {
            let c = PALETTE[i % PALETTE.len()];
            let pts: Vec<(f64, f64)> = ser
                .points
                .iter()
                .copied()
                .filter(|p| {
                    p.0.is_finite() && p.1.is_finite() && (!self.log_x || p.0 > 0.0) && (!self.log_y || p.1 > 0.0)
                })
                .collect();
            let dash = if ser.dashed { r#" stroke-dasharray="6 4""# } else { "" };
            if pts.len() > 1 {
                let d: Vec<String> = pts.iter().map(|p| format!("{:.1},{:.1}", sx(p.0), sy(p.1))).collect();
                let _ = writeln!(
                    s,
                    r#"<polyline fill="none" stroke="{c}" stroke-width="2"{dash} points="{}"/>"#,
                    d.join(" ")
                );
            }
            if pts.len() <= 40 {
                for p in &pts {
                    let _ = writeln!(s, r#"<circle cx="{:.1}" cy="{:.1}" r="3" fill="{c}"/>"#, sx(p.0), sy(p.1));
                }
            }
            let ly = top + 10.0 + 20.0 * i as f64;
            let lx = left + pw + 14.0;
            let _ = writeln!(
                s,
                r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{c}" stroke-width="2"{dash}/>"#,
                lx + 22.0
            );
            let _ = writeln!(s, r#"<text x="{}" y="{}">{}</text>"#, lx + 28.0, ly + 4.0, esc(&ser.name));
        }
        s.push_str("</svg>\n");
        s
    }
}

/// The machine, from `lscpu`, `/proc/meminfo`, `uname` and `rustc`.
pub fn machine_description() -> Vec<(String, String)> {
    let run = |cmd: &str, args: &[&str]| {
        std::process::Command::new(cmd)
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
    };
    let mut v = Vec::new();
    if let Some(l) = run("lscpu", &[]) {
        for key in ["Architecture", "Model name", "CPU(s)", "Thread(s) per core", "L2 cache", "L3 cache"] {
            if let Some(line) = l.lines().find(|x| x.trim_start().starts_with(&format!("{key}:"))) {
                let val = line.split_once(':').map(|x| x.1.trim()).unwrap_or("");
                v.push((format!("lscpu {key}"), val.to_string()));
            }
        }
    }
    if let Ok(m) = std::fs::read_to_string("/proc/meminfo") {
        if let Some(line) = m.lines().find(|l| l.starts_with("MemTotal:")) {
            v.push(("MemTotal".into(), line["MemTotal:".len()..].trim().to_string()));
        }
    }
    if let Some(u) = run("uname", &["-srm"]) {
        v.push(("kernel".into(), u.trim().to_string()));
    }
    if let Some(r) = run("rustc", &["--version"]) {
        v.push(("rustc".into(), r.trim().to_string()));
    }
    if let Some(l) = run("ldd", &["--version"]) {
        if let Some(first) = l.lines().next() {
            v.push(("libc".into(), first.trim().to_string()));
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats() {
        assert_eq!(count(1234567), "1,234,567");
        assert_eq!(count(12), "12");
        assert_eq!(mib(1024.0 * 1024.0 * 1.5), "1.50");
        let t = table(&["a", "b"], &[false, true], &[vec!["x".into(), "1".into()]]);
        assert_eq!(t, "| a | b |\n| --- | ---: |\n| x | 1 |\n");
    }

    #[test]
    fn chart_renders() {
        let c = Chart {
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            log_x: false,
            log_y: true,
            series: vec![Series { name: "a<b".into(), points: vec![(1.0, 10.0), (2.0, 1000.0)], dashed: false }],
        };
        let s = c.to_svg();
        assert!(s.starts_with("<svg") && s.contains("polyline") && s.contains("a&lt;b"));
    }
}
