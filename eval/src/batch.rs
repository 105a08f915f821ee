//! Many runs at once (`starc eval`): one row per building with every number of its report.json
//! under its dotted key, and per key the median, p10 and p90 per family and over all, and a strip
//! plot per headline figure.

use crate::error::{write, Result};
use serde::Serialize;
use serde_json::{json, Map, Value};
use starc_hil::gen::Family;
use std::collections::BTreeMap;
use std::path::Path;

/// The figures the summary line and the plots lead with.
pub const HEADLINE: [&str; 11] = [
    "inlier_ratio.pooled",
    "overlay.person_coverage",
    "overlay.people_shown",
    "detection.precision",
    "detection.recall",
    "alignment.accepted",
    "alignment.first_accepted_after_s",
    "alignment.first_error_m",
    "rig_pose_error.translation_m.p50",
    "robot_pose_error.rmse_m",
    "rig_lio_error.rmse_m",
];

/// One building.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub seed: u64,
    pub family: String,
    pub people: usize,
    pub duration_s: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    pub figures: BTreeMap<String, f64>,
}

impl Row {
    pub fn new(seed: u64, family: Family, people: usize, duration_s: f64, figures: BTreeMap<String, f64>) -> Self {
        Row { seed, family: family.to_string(), people, duration_s, error: None, figures }
    }

    pub fn failed(seed: u64, family: Option<Family>, error: &str) -> Self {
        let family = family.unwrap_or_else(|| Family::of_seed(seed)).to_string();
        Row { seed, family, people: 0, duration_s: 0.0, error: Some(error.to_string()), figures: BTreeMap::new() }
    }

    /// The headline figures that this row has, as `key value` pairs.
    pub fn headline(&self) -> String {
        let parts: Vec<String> =
            HEADLINE.iter().filter_map(|k| self.figures.get(*k).map(|v| format!("{k} {}", short(*v)))).collect();
        if parts.is_empty() {
            "no headline figure in its report".into()
        } else {
            parts.join(", ")
        }
    }
}

fn short(v: f64) -> String {
    if v.abs() >= 100.0 || v == v.trunc() {
        format!("{v:.0}")
    } else {
        format!("{v:.3}")
    }
}

/// Every number in a JSON document, keyed by its dotted path (array items by index); booleans
/// count as 0 or 1.
pub fn flatten(v: &Value) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    walk(v, String::new(), &mut out);
    out
}

fn walk(v: &Value, key: String, out: &mut BTreeMap<String, f64>) {
    let join = |k: &str| if key.is_empty() { k.to_string() } else { format!("{key}.{k}") };
    match v {
        Value::Number(n) => {
            if let Some(x) = n.as_f64().filter(|x| x.is_finite()) {
                out.insert(key, x);
            }
        }
        Value::Bool(b) => {
            out.insert(key, f64::from(u8::from(*b)));
        }
        Value::Object(m) => m.iter().for_each(|(k, v)| walk(v, join(k), out)),
        Value::Array(a) if a.len() <= 16 => a.iter().enumerate().for_each(|(i, v)| walk(v, join(&i.to_string()), out)),
        _ => {}
    }
}

/// p10, median and p90 of `v` (nearest rank on the sorted values).
pub fn spread(v: &mut [f64]) -> Value {
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v.get(((v.len() - 1) as f64 * q).round() as usize).copied();
    if v.is_empty() {
        return json!({ "n": 0 });
    }
    json!({ "n": v.len(), "p10": at(0.1), "median": at(0.5), "p90": at(0.9) })
}

/// Per key: the spread over all buildings and per family.
pub fn summarize(rows: &[Row]) -> Value {
    let mut groups: BTreeMap<String, Vec<&Row>> = BTreeMap::new();
    for r in rows.iter().filter(|r| r.error.is_none()) {
        groups.entry("all".into()).or_default().push(r);
        groups.entry(r.family.clone()).or_default().push(r);
    }
    let mut out = Map::new();
    for (group, members) in groups {
        let mut keys: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
        for r in &members {
            for (k, v) in &r.figures {
                keys.entry(k.as_str()).or_default().push(*v);
            }
        }
        let figures: Map<String, Value> = keys.into_iter().map(|(k, mut v)| (k.to_string(), spread(&mut v))).collect();
        out.insert(group, json!({ "buildings": members.len(), "figures": figures }));
    }
    Value::Object(out)
}

/// The headline figures' spreads, one line each, over all buildings.
pub fn print_summary(summary: &Value) {
    for k in HEADLINE {
        let s = &summary["all"]["figures"][k];
        if s["n"].as_u64().unwrap_or(0) > 0 {
            let f = |q: &str| s[q].as_f64().map_or("-".to_string(), short);
            println!("  {k:28} median {:>8}  p10 {:>8}  p90 {:>8}  (n = {})", f("median"), f("p10"), f("p90"), s["n"]);
        } else {
            println!("  {k:28} none of the buildings has it");
        }
    }
}

/// The headline figures' medians per family and over all, as a Markdown table (summary.md):
/// each cell is the median and, in brackets, how many buildings have the figure.
pub fn markdown_table(summary: &Value) -> String {
    use std::fmt::Write as _;
    let mut t = String::from("| buildings |");
    for k in HEADLINE {
        let _ = write!(t, " {k} |");
    }
    t.push_str("\n|---|");
    t.push_str(&"---|".repeat(HEADLINE.len()));
    t.push('\n');
    let Some(groups) = summary.as_object() else { return t };
    let order = std::iter::once("all".to_string()).chain(groups.keys().filter(|k| *k != "all").cloned());
    for group in order {
        let g = &summary[&group];
        let _ = write!(t, "| {group} ({}) |", g["buildings"]);
        for k in HEADLINE {
            let s = &g["figures"][k];
            match s["median"].as_f64() {
                Some(m) => {
                    let _ = write!(t, " {} ({}) |", short(m), s["n"]);
                }
                None => t.push_str(" - |"),
            }
        }
        t.push('\n');
    }
    t
}

/// The alignment goal over the buildings, as a line: of the rig sessions that saw the robot's
/// map, how many were placed right within 10 s of it, and how many accepted a wrong alignment.
/// Sessions that never saw the map are counted apart (no registration could place them).
pub fn alignment_goal(rows: &[Row]) -> String {
    // Rows that judged no second (alignment off, a rig that never started) say nothing.
    let judged = |r: &&Row| r.figures.get("alignment.map_sight.seconds_judged").is_some_and(|n| *n > 0.0);
    let scored: Vec<&Row> = rows.iter().filter(judged).collect();
    let saw: Vec<&&Row> =
        scored.iter().filter(|r| r.figures.contains_key("alignment.map_sight.sees_map_after_s")).collect();
    let in_time = saw.iter().filter(|r| r.figures.get("alignment.map_sight.right_within_10s") == Some(&1.0)).count();
    let wrong = |r: &Row| r.figures.get("alignment.accepted_wrong").copied().unwrap_or(0.0);
    let wrong_total: f64 = scored.iter().map(|r| wrong(r)).sum();
    let wrong_buildings = scored.iter().filter(|r| wrong(r) > 0.0).count();
    let rate =
        if saw.is_empty() { "-".to_string() } else { format!("{:.0} %", 100.0 * in_time as f64 / saw.len() as f64) };
    format!(
        "rig aligned right within 10 s of first seeing the robot's map: {in_time} of {} sessions that saw it ({rate}); \
         {} of {} never saw it; {wrong_total:.0} wrong alignments accepted, in {wrong_buildings} buildings",
        saw.len(),
        scored.len() - saw.len(),
        scored.len()
    )
}

/// One SVG per headline figure: each building a dot, by family, with the median as a line.
pub fn write_plots(rows: &[Row], dir: &Path) -> Result<usize> {
    std::fs::create_dir_all(dir).map_err(|source| crate::EvalError::Write { path: dir.to_path_buf(), source })?;
    let mut n = 0;
    for key in HEADLINE {
        let points: Vec<(usize, &str, f64)> = rows
            .iter()
            .enumerate()
            .filter_map(|(i, r)| r.figures.get(key).map(|v| (i, r.family.as_str(), *v)))
            .collect();
        if points.is_empty() {
            continue;
        }
        let svg = strip_plot(key, rows.len(), &points);
        write(&dir.join(format!("{key}.svg")), svg)?;
        n += 1;
    }
    Ok(n)
}

fn family_colour(family: &str) -> &'static str {
    match family {
        "flat" => "#1f77b4",
        "office" => "#ff7f0e",
        "warehouse" => "#2ca02c",
        "hall" => "#9467bd",
        "lab" => "#d62728",
        _ => "#555555",
    }
}

fn strip_plot(title: &str, count: usize, points: &[(usize, &str, f64)]) -> String {
    use std::fmt::Write as _;
    let (w, h, m) = (720.0, 320.0, 50.0);
    let lo = points.iter().map(|p| p.2).fold(f64::INFINITY, f64::min).min(0.0);
    let hi = points.iter().map(|p| p.2).fold(f64::NEG_INFINITY, f64::max).max(lo + 1e-9);
    let x = |i: usize| m + (w - 2.0 * m) * (i as f64 + 0.5) / count.max(1) as f64;
    let y = |v: f64| h - m - (h - 2.0 * m) * (v - lo) / (hi - lo);
    let mut s = String::new();
    let _ = write!(s, "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" font-family=\"sans-serif\" font-size=\"12\">");
    let _ = write!(s, "<rect width=\"{w}\" height=\"{h}\" fill=\"white\"/><text x=\"{m}\" y=\"20\" font-size=\"14\">{title}, per building</text>");
    let _ = write!(s, "<line x1=\"{m}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" stroke=\"black\"/>", h - m, w - m, h - m);
    let _ = write!(
        s,
        "<text x=\"5\" y=\"{:.0}\">{}</text><text x=\"5\" y=\"{:.0}\">{}</text>",
        y(hi) + 4.0,
        short(hi),
        y(lo) + 4.0,
        short(lo)
    );
    let mut values: Vec<f64> = points.iter().map(|p| p.2).collect();
    values.sort_by(f64::total_cmp);
    let median = values.get(values.len() / 2).copied().unwrap_or(lo);
    let _ = write!(
        s,
        "<line x1=\"{m}\" y1=\"{0:.1}\" x2=\"{1}\" y2=\"{0:.1}\" stroke=\"#888\" stroke-dasharray=\"4 3\"/>",
        y(median),
        w - m
    );
    for &(i, family, v) in points {
        let _ = write!(
            s,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"{}\"><title>{family} {}</title></circle>",
            x(i),
            y(v),
            family_colour(family),
            short(v)
        );
    }
    for (k, f) in Family::ALL.iter().enumerate() {
        let lx = m + 110.0 * k as f64;
        let _ = write!(
            s,
            "<circle cx=\"{lx}\" cy=\"{}\" r=\"4\" fill=\"{}\"/><text x=\"{}\" y=\"{}\">{f}</text>",
            h - 15.0,
            family_colour(f.name()),
            lx + 8.0,
            h - 11.0
        );
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_alignment_goal_counts_only_sessions_that_saw_the_map() {
        let row = |figures: &[(&str, f64)]| {
            let f = figures.iter().map(|(k, v)| (k.to_string(), *v)).collect();
            Row::new(1000, Family::Flat, 1, 30.0, f)
        };
        let judged = ("alignment.map_sight.seconds_judged", 20.0);
        let rows = [
            row(&[
                judged,
                ("alignment.map_sight.sees_map_after_s", 3.0),
                ("alignment.map_sight.right_within_10s", 1.0),
            ]),
            row(&[
                judged,
                ("alignment.map_sight.sees_map_after_s", 5.0),
                ("alignment.map_sight.right_within_10s", 0.0),
            ]),
            row(&[judged, ("alignment.accepted_wrong", 2.0)]),
            row(&[("detection.recall", 0.5)]),
        ];
        let line = alignment_goal(&rows);
        assert!(line.contains("1 of 2 sessions that saw it (50 %)"), "{line}");
        assert!(line.contains("1 of 3 never saw it"), "{line}");
        assert!(line.contains("2 wrong alignments accepted, in 1 buildings"), "{line}");
    }

    #[test]
    fn flatten_keys_every_number_by_its_path() {
        let v = json!({ "inlier": { "ratio": 0.9, "frames": 12 }, "ok": true, "name": "x", "q": [1.0, 2.0] });
        let f = flatten(&v);
        assert_eq!(f.get("inlier.ratio"), Some(&0.9));
        assert_eq!(f.get("inlier.frames"), Some(&12.0));
        assert_eq!(f.get("ok"), Some(&1.0));
        assert_eq!(f.get("q.1"), Some(&2.0));
        assert!(!f.contains_key("name"));
    }

    #[test]
    fn the_markdown_table_has_a_row_per_group() {
        let rows = vec![
            Row::new(1, Family::Flat, 1, 30.0, [("detection.recall".to_string(), 0.5)].into_iter().collect()),
            Row::new(2, Family::Lab, 1, 30.0, BTreeMap::new()),
        ];
        let table = markdown_table(&summarize(&rows));
        assert!(
            table.contains("| all (2) |") && table.contains("| flat (1) |") && table.contains("| lab (1) |"),
            "{table}"
        );
        assert!(table.contains(" 0.500 (1) |"), "{table}");
    }

    #[test]
    fn summary_per_family_and_over_all() {
        let row = |seed, family, v: f64| {
            Row::new(seed, family, 1, 30.0, [("inlier.ratio".to_string(), v)].into_iter().collect())
        };
        let mut rows: Vec<Row> = (0..10).map(|i| row(i, Family::Flat, f64::from(i as u8) / 10.0)).collect();
        rows.push(row(10, Family::Hall, 0.5));
        rows.push(Row::failed(11, Some(Family::Hall), "boom"));
        let s = summarize(&rows);
        assert_eq!(s["all"]["buildings"], 11);
        assert_eq!(s["flat"]["figures"]["inlier.ratio"]["median"], 0.5);
        assert_eq!(s["flat"]["figures"]["inlier.ratio"]["p10"], 0.1);
        assert_eq!(s["flat"]["figures"]["inlier.ratio"]["p90"], 0.8);
        assert_eq!(s["hall"]["buildings"], 1);
    }
}
