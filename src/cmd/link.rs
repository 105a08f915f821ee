//! `starc link certs --out DIR`: the private CA and the robot's and rig's certificates for the
//! link's mutual TLS (`starc_link::certs`), and where each file goes.

use starc_link::certs::{make_certs, DEFAULT_ROBOT_HOSTS};
use std::path::PathBuf;

#[derive(clap::Subcommand)]
pub enum Command {
    /// Make a private CA and the robot's and rig's certificates and keys (keys 0600).
    Certs(CertsArgs),
}

#[derive(clap::Args)]
pub struct CertsArgs {
    /// Where to write ca.pem, ca.key, robot.pem, robot.key, rig.pem, rig.key (created 0700).
    /// The default is where config/robot.toml and config/fpv.toml look for them.
    #[arg(long, default_value = "config/certs")]
    pub out: PathBuf,
    /// An IP or DNS name the rig dials the robot at (repeat for each); the rig checks the
    /// robot's certificate names it. Default: the shipped configs' 192.168.50.2, 127.0.0.1 and
    /// localhost.
    #[arg(long = "robot-host")]
    pub robot_hosts: Vec<String>,
    /// Replace existing files (a new CA: both ends need the new files).
    #[arg(long)]
    pub force: bool,
}

pub fn run(cmd: Command) -> anyhow::Result<()> {
    match cmd {
        Command::Certs(a) => certs(a),
    }
}

fn certs(a: CertsArgs) -> anyhow::Result<()> {
    let hosts = if a.robot_hosts.is_empty() {
        DEFAULT_ROBOT_HOSTS.iter().map(|s| s.to_string()).collect()
    } else {
        a.robot_hosts
    };
    let f = make_certs(&a.out, &hosts, a.force)?;
    let show = |p: &PathBuf| p.display().to_string();
    println!("wrote a private CA and two certificates in {} (robot names: {})", a.out.display(), hosts.join(", "));
    println!();
    println!("robot (config/robot.toml [link.tls] reads config/certs/ beside it):");
    println!("  {}  {}  {}", show(&f.ca_cert), show(&f.robot_cert), show(&f.robot_key));
    println!("rig (config/fpv.toml [link.tls] reads config/certs/ beside it):");
    println!("  {}  {}  {}", show(&f.ca_cert), show(&f.rig_cert), show(&f.rig_key));
    println!();
    println!("Copy each set into that host's config/certs/ (keys stay mode 0600, e.g. scp -p or");
    println!("install -m 600). Keep {} offline: it is only needed to make new certificates,", show(&f.ca_key));
    println!("and whoever holds it can make a rig the robot trusts.");
    Ok(())
}
