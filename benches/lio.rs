//! `cargo bench --bench lio`: the LIO against ground truth and KISS-ICP on every shipped
//! scenario, robot and rig, in one run.
//!
//! For each scenario: `starc sim` (no camera), `starc lio --dump-scans` on its pcap (timing and
//! memory from its lio.json), then `tests/peers/lio_eval.py` per device, which scores our TUM
//! trajectory and KISS-ICP's on the same scans with evo (APE after SE(3) alignment, RPE per
//! metre) and times KISS-ICP (single thread). Prints one table; writes everything under
//! `target/lio-bench/` (set `STARC_LIO_BENCH_PLOTS=DIR` to put the trajectory plots there too).
//! Use `STARC_LIO_BENCH_SCENARIOS=lab,corridor` to run fewer.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const DEVICES: [(&str, &str, &str); 2] =
    [("robot", "192.168.1.101", "gt_robot.tum"), ("rig", "192.168.2.102", "gt_fpv.tum")];

fn run(cmd: &mut Command) -> Result<String, String> {
    let out = cmd.output().map_err(|e| format!("{cmd:?}: {e}"))?;
    if !out.status.success() {
        return Err(format!("{cmd:?} failed: {}", String::from_utf8_lossy(&out.stderr)));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

fn f(v: &Value, path: &[&str]) -> f64 {
    let mut v = v;
    for k in path {
        v = &v[*k];
    }
    v.as_f64().unwrap_or(f64::NAN)
}

fn main() -> Result<(), String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let starc = PathBuf::from(env!("CARGO_BIN_EXE_starc"));
    let python = root.join(".venv/bin/python");
    if !python.exists() {
        return Err(format!(
            "{} missing: run .ci/run once (or create the venv from tests/peers/requirements.txt)",
            python.display()
        ));
    }
    let out_dir = root.join("target/lio-bench");
    let plots = std::env::var_os("STARC_LIO_BENCH_PLOTS").map(PathBuf::from);
    let scenarios: Vec<String> = std::env::var("STARC_LIO_BENCH_SCENARIOS")
        .unwrap_or_else(|_| "lab,auditorium,tactical,corridor".into())
        .split(',')
        .map(str::to_string)
        .collect();
    let mut rows = Vec::new();
    let mut all = Vec::new();
    for s in &scenarios {
        let dir = out_dir.join(s);
        let began = Instant::now();
        run(Command::new(&starc).args(["sim", s, "--no-camera", "--out"]).arg(&dir))?;
        let sim_s = began.elapsed().as_secs_f64();
        let lio_dir = dir.join("lio");
        run(Command::new(&starc).arg("lio").arg(dir.join("avia.pcap")).arg("--out").arg(&lio_dir).arg("--dump-scans"))?;
        let summary: Value = serde_json::from_str(
            &std::fs::read_to_string(lio_dir.join("lio.json")).map_err(|e| format!("lio.json: {e}"))?,
        )
        .map_err(|e| e.to_string())?;
        eprintln!("{s}: simulated in {sim_s:.1} s, LIO in {:.1} s", f(&summary, &["wall_s"]));
        for (name, ip, gt) in DEVICES {
            let dev = summary["devices"]
                .as_array()
                .and_then(|d| d.iter().find(|d| d["device"] == ip))
                .ok_or(format!("{s}: no {ip} in lio.json"))?;
            let mut eval = Command::new(&python);
            eval.arg(root.join("tests/peers/lio_eval.py"))
                .arg("--gt")
                .arg(dir.join(gt))
                .arg("--ours")
                .arg(lio_dir.join(format!("{ip}.tum")))
                .arg("--scans")
                .arg(lio_dir.join(format!("{ip}_scans.bin")))
                .arg("--kiss-out")
                .arg(lio_dir.join(format!("{ip}_kiss_icp.tum")))
                .arg("--title")
                .arg(format!("{s} / {name}"));
            let plot_dir = plots.clone().unwrap_or_else(|| out_dir.clone());
            eval.arg("--plot").arg(plot_dir.join(format!("lio_{s}_{name}.png")));
            let line = run(&mut eval)?;
            let r: Value = serde_json::from_str(line.trim()).map_err(|e| format!("{e}: {line}"))?;
            rows.push(format!(
                "| {s} | {name} | {:.1} / {:.1} | {:.2} | {:.1} / {:.1} | {:.2} | {:.2} / {:.2} | {:.2} / {:.2} | {:.1}x | {} | {} |",
                f(&r, &["ours", "ape_rmse_m"]) * 100.0,
                f(&r, &["ours", "ape_max_m"]) * 100.0,
                f(&r, &["ours", "rpe_rmse_m_per_m"]) * 100.0,
                f(&r, &["kiss_icp", "ape_rmse_m"]) * 100.0,
                f(&r, &["kiss_icp", "ape_max_m"]) * 100.0,
                f(&r, &["kiss_icp", "rpe_rmse_m_per_m"]) * 100.0,
                f(dev, &["time_per_scan_ms_median"]),
                f(dev, &["time_per_scan_ms_p99"]),
                f(&r, &["kiss_icp", "time_ms_median"]),
                f(&r, &["kiss_icp", "time_ms_p99"]),
                f(&r, &["kiss_icp", "time_ms_median"]) / f(dev, &["time_per_scan_ms_median"]),
                dev["map_points"],
                dev["health"].as_object().map_or(String::new(), |h| h
                    .iter()
                    .filter(|(_, v)| v.as_u64().unwrap_or(0) > 0)
                    .map(|(k, v)| format!("{k} {v}"))
                    .collect::<Vec<_>>()
                    .join(", ")),
            ));
            all.push(serde_json::json!({"scenario": s, "device": name, "eval": r, "lio": dev, "peak_rss_mib": summary["peak_rss_mib"]}));
        }
        println!("{s}: starc lio peak memory (both devices, whole process) {:.1} MiB", f(&summary, &["peak_rss_mib"]));
    }
    println!();
    println!("| scenario | device | ours APE RMSE / max (cm) | ours RPE (cm/m) | KISS-ICP APE RMSE / max (cm) | KISS-ICP RPE (cm/m) | ours ms/scan median / p99 | KISS-ICP ms/scan median / p99 | KISS-ICP / ours time | map points | health (scans) |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &rows {
        println!("{r}");
    }
    std::fs::write(out_dir.join("results.json"), serde_json::to_string_pretty(&all).map_err(|e| e.to_string())?)
        .map_err(|e| e.to_string())?;
    Ok(())
}
