//! TLS with a throwaway CA made by the openssl CLI (a rig with another CA's certificate, or with
//! the robot's, never comes up), and zenoh access control from a user's file denying one key.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use common::{collect, fast, open_listening, rig_cfg, robot_cfg, wait_up};
use nalgebra::Isometry3;
use starc_link::{host_now_ns, LinkConfig, LinkMessage, LinkNode, LinkState, Role, TlsConfig};
use starc_time::{Clock, Stamp};

fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("/usr/bin/openssl").args(args).current_dir(dir).output().expect("openssl CLI");
    assert!(out.status.success(), "openssl {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// A CA (`<name>-ca.pem`) and two leaves for 127.0.0.1 signed by it: `<name>-robot.pem` and
/// `<name>-rig.pem` (with their `.key`), named `starc-robot` and `starc-rig` as `starc link certs`
/// names them (with mutual TLS the link grants each role by that name: acl::zenoh_access_control).
fn make_pki(dir: &Path, name: &str) {
    let ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"];
    let ca_key = format!("{name}-ca.key");
    let ca = format!("{name}-ca.pem");
    let mut a = vec!["req", "-x509"];
    a.extend(ec);
    a.extend(["-keyout", &ca_key, "-out", &ca, "-days", "2", "-subj", "/CN=starc test CA"]);
    a.extend(["-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign"]);
    openssl(dir, &a);
    let ext = format!("{name}.ext");
    std::fs::write(
        dir.join(&ext),
        "subjectAltName=IP:127.0.0.1\nbasicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\nextendedKeyUsage=serverAuth,clientAuth\n",
    )
    .unwrap();
    for (leaf, cn) in [("robot", "starc-robot"), ("rig", "starc-rig")] {
        let key = format!("{name}-{leaf}.key");
        let csr = format!("{name}-{leaf}.csr");
        let subj = format!("/CN={cn}");
        let mut a = vec!["req"];
        a.extend(ec);
        a.extend(["-keyout", &key, "-out", &csr, "-subj", &subj]);
        openssl(dir, &a);
        let pem = format!("{name}-{leaf}.pem");
        openssl(
            dir,
            &[
                "x509",
                "-req",
                "-in",
                &csr,
                "-CA",
                &ca,
                "-CAkey",
                &ca_key,
                "-CAcreateserial",
                "-out",
                &pem,
                "-days",
                "2",
                "-extfile",
                &ext,
            ],
        );
    }
}

fn tls_cfg(dir: &Path, listen: Vec<String>, connect: Vec<String>, ca: &str, leaf: &str) -> LinkConfig {
    LinkConfig {
        tls: Some(TlsConfig {
            root_ca: dir.join(format!("{ca}-ca.pem")),
            cert: Some(dir.join(format!("{leaf}.pem"))),
            key: Some(dir.join(format!("{leaf}.key"))),
            mutual: true,
            verify_name: true,
        }),
        ..fast(listen, connect)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tls_link_with_a_private_ca_and_a_stranger_refused() {
    let dir = tempfile::tempdir().unwrap();
    make_pki(dir.path(), "good");
    make_pki(dir.path(), "other");
    let tls_ep = |port: u16| format!("tls/127.0.0.1:{port}");
    let (robot, port) =
        open_listening(|port| tls_cfg(dir.path(), vec![tls_ep(port)], vec![], "good", "good-robot"), Role::Robot).await;
    let ep = tls_ep(port);

    // A rig trusting another CA (and holding a certificate from it) never gets a link.
    let stranger =
        LinkNode::open(&tls_cfg(dir.path(), vec![], vec![ep.clone()], "other", "other-rig"), Role::Rig).await.unwrap();
    assert!(!wait_up(&stranger, Duration::from_millis(1500)).await, "{:?}", stranger.health());
    assert_eq!(robot.health().state, LinkState::Lost);
    stranger.close().await.unwrap();

    // Nor does a rig showing the robot's certificate (right CA, the robot's name): the role comes
    // with the name, and the robot's role sends nothing a robot would take (zenoh's access
    // control drops its rig heartbeats on arrival, and the robot's own messages on the way out).
    let impostor =
        LinkNode::open(&tls_cfg(dir.path(), vec![], vec![ep.clone()], "good", "good-robot"), Role::Rig).await.unwrap();
    assert!(!wait_up(&impostor, Duration::from_millis(1500)).await, "{:?}", impostor.health());
    assert_eq!(robot.health().state, LinkState::Lost);
    impostor.close().await.unwrap();

    // The rig with the right CA and its own certificate does, and messages flow.
    let mut rig = LinkNode::open(&tls_cfg(dir.path(), vec![], vec![ep], "good", "good-rig"), Role::Rig).await.unwrap();
    assert!(wait_up(&rig, Duration::from_secs(5)).await, "{:?}", rig.health());
    // Poses are droppable, and "up" comes from heartbeats, which can arrive before the rig's pose
    // subscription has reached the robot: a busy host may lose the first one, so a round that
    // brings nothing is sent again, five rounds at most.
    let pose =
        LinkMessage::RobotPose { stamp: Stamp::new(host_now_ns(), Clock::Ptp), world_t_lidar: Isometry3::identity() };
    let mut got = Vec::new();
    for _round in 0..5 {
        robot.publish(&pose).await.unwrap();
        got = collect(&mut rig, Duration::from_secs(1), |g| !g.is_empty()).await;
        if !got.is_empty() {
            break;
        }
    }
    assert_eq!(got.first().map(|r| &r.msg), Some(&pose));
    rig.close().await.unwrap();
    robot.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn access_control_denies_one_key() {
    let dir = tempfile::tempdir().unwrap();
    // The rig refuses robot poses coming in; everything else is allowed.
    let acl = r#"{
      access_control: {
        enabled: true,
        default_permission: "allow",
        rules: [{ id: "no_pose", messages: ["put"], flows: ["ingress"], permission: "deny",
                  key_exprs: ["starc/robot/pose"] }],
        subjects: [{ id: "everyone" }],
        policies: [{ rules: ["no_pose"], subjects: ["everyone"] }],
      },
    }"#;
    let path = dir.path().join("rig_zenoh.json5");
    std::fs::write(&path, acl).unwrap();
    let (robot, port) = open_listening(robot_cfg, Role::Robot).await;
    let mut rig = LinkNode::open(&LinkConfig { zenoh_config: Some(path), ..rig_cfg(port) }, Role::Rig).await.unwrap();
    assert!(wait_up(&rig, Duration::from_secs(5)).await, "{:?}", rig.health());
    let probe = LinkMessage::Detections {
        seq: 9,
        stamp: Stamp::new(1, Clock::Ptp),
        scan_last_packet_host_ns: 2,
        sent_host_ns: 3,
        people: vec![],
    };
    // Poses, then detections; this test is about the denial, so a round whose detections a busy
    // host dropped (they are droppable) is simply sent again, three rounds at most.
    let mut got = Vec::new();
    for _round in 0..3 {
        for i in 0..5 {
            robot
                .publish(&LinkMessage::RobotPose {
                    stamp: Stamp::new(i, Clock::Ptp),
                    world_t_lidar: Isometry3::identity(),
                })
                .await
                .unwrap();
        }
        robot.publish(&probe).await.unwrap();
        got.extend(collect(&mut rig, Duration::from_secs(1), |g| g.iter().any(|r| r.msg == probe)).await);
        if got.iter().any(|r| r.msg == probe) {
            break;
        }
    }
    // Stragglers get 300 ms more.
    got.extend(collect(&mut rig, Duration::from_millis(300), |_| false).await);
    assert!(got.iter().any(|r| r.msg == probe), "detections did not arrive");
    assert!(!got.iter().any(|r| matches!(r.msg, LinkMessage::RobotPose { .. })), "a denied pose arrived");
    rig.close().await.unwrap();
    robot.close().await.unwrap();
}
