//! `starc gen` and `starc eval`: a generated building is an ordinary scenario file that `starc
//! sim` runs, the same seed gives the same file, a route through a wall is refused, and a short
//! evaluation writes eval.json with its rows, summary and plots.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::Command;

fn starc(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_starc")).args(args).output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (out.status.success(), text)
}

#[test]
fn gen_writes_a_scenario_that_sim_runs_and_the_same_seed_twice() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.toml"), dir.path().join("b.toml"));
    let svg = dir.path().join("a.svg");
    let (ok, text) = starc(&[
        "gen",
        "--seed",
        "12",
        "--family",
        "flat",
        "--out",
        a.to_str().unwrap(),
        "--svg",
        svg.to_str().unwrap(),
    ]);
    assert!(ok && text.contains("flat seed 12 (development set)"), "{text}");
    let (ok, text) = starc(&["gen", "--seed", "12", "--family", "flat", "--out", b.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert!(std::fs::read_to_string(&svg).unwrap().starts_with("<svg"));
    let (ok, text) = starc(&["gen", "--seed", "1003", "--family", "castle", "--out", b.to_str().unwrap()]);
    assert!(!ok && text.contains("unknown family"), "{text}");
    let run = dir.path().join("run");
    let (ok, text) =
        starc(&["sim", a.to_str().unwrap(), "--duration", "2", "--sensors-only", "--out", run.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(run.join("avia.pcap").exists());
}

#[test]
fn sim_refuses_a_route_through_a_wall() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wall.toml");
    let text = "name = \"t\"\n[[floors]]\nmin = [-1, -1]\nmax = [10, 5]\n[[walls]]\nfrom = [5, -1]\nto = [5, 5]\n[robot]\nwaypoints = [[1, 2, 0], [9, 2, 0]]\n[responder]\nwaypoints = [[1, 1]]\n";
    std::fs::write(&path, text).unwrap();
    let (ok, out) =
        starc(&["sim", path.to_str().unwrap(), "--sensors-only", "--out", dir.path().join("o").to_str().unwrap()]);
    assert!(!ok && out.contains("robot's leg 0 meets wall at (4.8"), "{out}");
}

/// Seed 17's responder powers on at 9.2 s: 18 s leave the rig several seconds of scans.
#[test]
fn eval_writes_rows_a_summary_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("eval");
    let (ok, text) =
        starc(&["eval", "--seeds", "17..17", "--offline", "--max-duration", "18", "--out", out.to_str().unwrap()]);
    assert!(ok, "{text}");
    let eval: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
    assert_eq!(eval["buildings"], 1);
    assert_eq!(eval["test_set"], false);
    assert_eq!(eval["max_duration_s"], 18.0);
    assert_eq!(eval["hint"], "none");
    let row = &eval["rows"][0];
    assert!(row["error"].is_null(), "{row}");
    assert!(row["figures"]["detection.windows"].as_f64().unwrap() > 10.0, "{row}");
    assert!(eval["summary"]["all"]["figures"]["detection.windows"]["median"].is_number(), "{eval}");
    let family = row["family"].as_str().unwrap();
    assert_eq!(eval["summary"][family]["buildings"], 1);
    let building = out.join(format!("{family}-17"));
    assert!(building.join("plan.svg").exists() && building.join("mission/report.json").exists());
    // No silent drift: every stretch where the robot's pose error grew by more than 10 cm within
    // 5 s was flagged by the LIO's health (the odometry issue's health test, on a generated
    // building).
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(building.join("mission/report.json")).unwrap()).unwrap();
    let drift = &report["robot_pose_error"]["drift"];
    assert_eq!(drift["silent"], 0, "{drift}");
    assert!(!building.join("avia.pcap").exists(), "the pcap is removed without --keep");
    assert!(std::fs::read_dir(out.join("plots")).unwrap().count() >= 3);
    let (ok, text) = starc(&["eval", "--seeds", "998..1001", "--offline", "--out", out.to_str().unwrap()]);
    assert!(!ok && text.contains("mixes development seeds"), "{text}");
}

/// `--no-wall-timing`: the rig's searches take no time, so two runs of one building write the
/// same report, byte for byte; the live mode refuses it.
#[test]
fn eval_without_wall_timing_repeats_itself() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str| {
        let out = dir.path().join(name);
        let args = ["eval", "--seeds", "17..17", "--offline", "--max-duration", "18", "--no-wall-timing", "--out"];
        let (ok, text) = starc(&[&args[..], &[out.to_str().unwrap()]].concat());
        assert!(ok, "{text}");
        let eval: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
        assert_eq!(eval["wall_timing"], false);
        let family = eval["rows"][0]["family"].as_str().unwrap().to_string();
        std::fs::read_to_string(out.join(format!("{family}-17/mission/report.json"))).unwrap()
    };
    let (a, b) = (run("a"), run("b"));
    let report: serde_json::Value = serde_json::from_str(&a).unwrap();
    assert!(report["alignment"].is_object(), "{report}");
    assert!(a == b, "two runs without wall timing differ");
    let out = dir.path().join("live");
    let (ok, text) = starc(&["eval", "--seeds", "17..17", "--no-wall-timing", "--out", out.to_str().unwrap()]);
    assert!(!ok && text.contains("--no-wall-timing is for offline runs"), "{text}");
}

/// `starc dataset --clusters` on a short run of one development building: the four arrays numpy
/// reads, a box per person per window, the cluster table, and the test seeds refused without
/// `--test-set`.
#[test]
fn dataset_writes_windows_and_boxes_and_keeps_test_seeds_apart() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ds");
    let (ok, text) = starc(&["dataset", "--seeds", "1000..1000", "--out", out.to_str().unwrap()]);
    assert!(!ok && text.contains("test set"), "{text}");
    let (ok, text) = starc(&[
        "dataset",
        "--seeds",
        "2..2",
        "--max-duration",
        "8",
        "--out",
        out.to_str().unwrap(),
        "--jobs",
        "1",
        "--clusters",
    ]);
    assert!(ok, "{text}");
    let building = out.join("warehouse-2");
    let npy_shape = |name: &str| {
        let bytes = std::fs::read(building.join(name)).unwrap();
        assert_eq!(&bytes[..6], b"\x93NUMPY", "{name}");
        let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        let header = String::from_utf8(bytes[10..10 + len].to_vec()).unwrap();
        let shape = header.split("'shape': (").nth(1).unwrap().split(')').next().unwrap().to_string();
        let dims: Vec<usize> = shape.split(',').filter_map(|d| d.trim().parse().ok()).collect();
        let item = if header.contains("'<i2'") || header.contains("'<u2'") {
            2
        } else if header.contains("'<i8'") {
            8
        } else {
            4
        };
        assert_eq!(bytes.len() - 10 - len, dims.iter().product::<usize>() * item, "{name}: {header}");
        dims
    };
    let points = npy_shape("points.npy");
    let windows = npy_shape("windows.npy");
    let boxes = npy_shape("boxes.npy");
    assert_eq!(npy_shape("labels.npy"), vec![points[0]]);
    assert!(windows[0] >= 5 && points[0] > windows[0] * 10_000, "{windows:?} windows, {points:?} points: {text}");
    // Every window lists every person in the building (seen or not).
    assert_eq!(boxes[1], 10);
    assert_eq!(boxes[0] % windows[0], 0, "{boxes:?} boxes over {windows:?} windows");
    // --clusters: a row per cluster the detector judged, the trees' inputs then the truth.
    let clusters = npy_shape("clusters.npy");
    assert_eq!(clusters[1], starc_eval::clusters::COLUMNS);
    assert!(clusters[0] >= windows[0], "{clusters:?} clusters over {windows:?} windows");
    let meta = std::fs::read_to_string(building.join("meta.json")).unwrap();
    assert!(meta.contains("\"set\": \"development\""), "{meta}");
    assert!(!out.join("sim").join("warehouse-2").exists(), "the simulator's run is removed");
}
