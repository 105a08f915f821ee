//! A master and a slave joined by a simulated network: known clock offset, skew and path delay
//! in, the slave's measurements checked against them.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use super::*;
use crate::config::{MasterConfig, SlaveConfig};
use crate::message::{ClockIdentity, PortIdentity};
use crate::servo::ServoState;
use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap};

const T0: i128 = 1_780_000_000_000_000_000;

fn pid(last: u8) -> PortIdentity {
    PortIdentity { clock: ClockIdentity([2, 0, 0, 0xff, 0xfe, 0, 0, last]), port: 1 }
}

#[derive(Clone, Debug)]
enum Ev {
    Timer(usize, Timer),
    Deliver { to: usize, event: bool, data: Vec<u8> },
    TxStamp(usize, TxTag),
}

/// Node 0..n with local clocks `local(T) = T + offset + skew * (T - T0)`.
struct Net {
    ports: Vec<Port>,
    clocks: Vec<(i128, f64)>,
    /// One-way delays (ns) each direction: to node i from others.
    delay_to: Vec<i128>,
    jitter_ns: i128,
    queue: BinaryHeap<Reverse<(i128, u64)>>,
    events: BTreeMap<u64, Ev>,
    timers: BTreeMap<(usize, Timer), u64>,
    next_id: u64,
    rng: u64,
    samples: Vec<(i128, SlaveSample)>,
    actions_seen: Vec<Action>,
    start: i128,
}

impl Net {
    fn new(ports: Vec<Port>, clocks: Vec<(i128, f64)>, delay_to: Vec<i128>, jitter_ns: i128) -> Self {
        Self {
            ports,
            clocks,
            delay_to,
            jitter_ns,
            queue: BinaryHeap::new(),
            events: BTreeMap::new(),
            timers: BTreeMap::new(),
            next_id: 0,
            rng: 7,
            samples: Vec::new(),
            actions_seen: Vec::new(),
            start: T0,
        }
    }

    fn local(&self, node: usize, t: i128) -> u64 {
        let (offset, skew) = self.clocks[node];
        (t + offset + ((t - T0) as f64 * skew) as i128) as u64
    }

    fn jitter(&mut self) -> i128 {
        self.rng = self.rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        if self.jitter_ns == 0 {
            return 0;
        }
        ((self.rng >> 33) as i128 % (2 * self.jitter_ns + 1)) - self.jitter_ns
    }

    fn schedule(&mut self, at: i128, ev: Ev) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        self.events.insert(id, ev);
        self.queue.push(Reverse((at, id)));
        id
    }

    fn apply(&mut self, node: usize, now: i128, actions: Vec<Action>) {
        for a in actions {
            self.actions_seen.push(a.clone());
            match a {
                Action::ArmTimer { timer, after } => {
                    let id = self.schedule(now + after.as_nanos() as i128, Ev::Timer(node, timer));
                    self.timers.insert((node, timer), id);
                }
                Action::SendEvent { data, tag } => {
                    self.schedule(now + 1_000, Ev::TxStamp(node, tag));
                    self.broadcast(node, now, true, data);
                }
                Action::SendGeneral { data } => self.broadcast(node, now, false, data),
                Action::StepClock { .. } | Action::SetFrequency { .. } => {}
            }
        }
    }

    fn broadcast(&mut self, from: usize, now: i128, event: bool, data: Vec<u8>) {
        for to in 0..self.ports.len() {
            if to != from {
                let at = now + self.delay_to[to] + self.jitter();
                self.schedule(at, Ev::Deliver { to, event, data: data.clone() });
            }
        }
    }

    fn run(&mut self, seconds: i128) {
        for node in 0..self.ports.len() {
            let a = self.ports[node].start();
            self.apply(node, self.start, a);
        }
        let end = self.start + seconds * 1_000_000_000;
        while let Some(Reverse((at, id))) = self.queue.pop() {
            if at > end {
                break;
            }
            let Some(ev) = self.events.remove(&id) else { continue };
            let (node, actions) = match ev {
                Ev::Timer(node, timer) => {
                    if self.timers.get(&(node, timer)) != Some(&id) {
                        continue; // re-armed since
                    }
                    let now = self.local(node, at);
                    (node, self.ports[node].handle_timer(timer, now))
                }
                Ev::Deliver { to, event, data } => {
                    let rx = self.local(to, at);
                    let a = if event {
                        self.ports[to].handle_event(&data, rx)
                    } else {
                        self.ports[to].handle_general(&data, rx)
                    };
                    (to, a)
                }
                Ev::TxStamp(node, tag) => {
                    let tx = self.local(node, at - 1_000);
                    (node, self.ports[node].handle_tx_timestamp(tag, tx))
                }
            };
            if let Port::Slave(s) = &self.ports[node] {
                if let Some(sample) = s.latest() {
                    if self.samples.last().map(|(_, l)| l.local_ns) != Some(sample.local_ns) {
                        self.samples.push((at, sample));
                    }
                }
            }
            self.apply(node, at, actions);
        }
    }
}

fn fast_master(domain: u8) -> MasterConfig {
    MasterConfig { domain, log_announce_interval: -2, log_sync_interval: -3, ..MasterConfig::default() }
}

fn fast_slave(domain: u8) -> SlaveConfig {
    SlaveConfig { domain, log_min_delay_req_interval: -3, ..SlaveConfig::default() }
}

#[test]
fn slave_measures_offset_delay_and_skew_of_a_ptp_timescale_master() {
    let master = Port::Master(Master::new(fast_master(0), pid(1)));
    let slave = Port::Slave(Slave::new(fast_slave(0), pid(2)));
    // Slave 250 us ahead and 40 ppm fast; 35 us each way, +-2 us jitter.
    let (offset, skew) = (250_000i128, 40e-6);
    let mut net = Net::new(vec![master, slave], vec![(0, 0.0), (offset, skew)], vec![35_000, 35_000], 2_000);
    net.run(20);
    let Port::Slave(s) = &net.ports[1] else { unreachable!() };
    assert_eq!(s.state(), SlaveState::Slave);
    assert_eq!(s.selected_master(), Some(pid(1)));
    assert!(net.samples.len() > 100, "{} samples", net.samples.len());
    let mut worst = 0i128;
    for (at, sample) in net.samples.iter().skip(20) {
        // The true offset when the Sync arrived.
        let truth = offset + ((*at - T0) as f64 * skew) as i128;
        worst = worst.max((sample.offset_ns as i128 - truth).abs());
        assert_eq!(sample.utc_offset_s, 37, "PTP timescale: 37 s taken off");
    }
    let last = net.samples.last().unwrap().1;
    println!(
        "simulated: worst |offset error| {worst} ns, delay {} ns (true 35000), freq {:.0} ppb (true 40000), stats {:?}",
        last.path_delay_ns,
        last.freq_ppb,
        s.stats()
    );
    // One Sync's jitter (2 us) plus the median delay's error.
    assert!(worst < 4_000, "offset error {worst} ns");
    assert!((last.path_delay_ns - 35_000).abs() < 2_000, "{last:?}");
    assert!((last.freq_ppb - 40_000.0).abs() < 200.0, "{last:?}");
    assert_eq!(last.state, ServoState::Jump, "250 us is past the 20 us step threshold");
    assert!(!net.actions_seen.iter().any(|a| matches!(a, Action::StepClock { .. } | Action::SetFrequency { .. })));
}

#[test]
fn asymmetric_path_shows_as_half_the_asymmetry() {
    let master = Port::Master(Master::new(fast_master(0), pid(1)));
    let slave = Port::Slave(Slave::new(fast_slave(0), pid(2)));
    // 20 us to the slave, 60 us back: E2E sees delay 40 us and an offset error of -20 us.
    let mut net = Net::new(vec![master, slave], vec![(0, 0.0), (0, 0.0)], vec![60_000, 20_000], 0);
    net.run(5);
    let last = net.samples.last().unwrap().1;
    assert_eq!(last.path_delay_ns, 40_000);
    assert_eq!(last.offset_ns, -20_000);
}

#[test]
fn arb_master_time_is_compared_as_is() {
    let cfg = MasterConfig { ptp_timescale: false, ..fast_master(0) };
    let master = Port::Master(Master::new(cfg, pid(1)));
    let slave = Port::Slave(Slave::new(fast_slave(0), pid(2)));
    let mut net = Net::new(vec![master, slave], vec![(0, 0.0), (-5_000, 0.0)], vec![10_000, 10_000], 0);
    net.run(5);
    let last = net.samples.last().unwrap().1;
    assert_eq!(last.utc_offset_s, 0);
    assert_eq!(last.offset_ns, -5_000);
    assert_eq!(last.state, ServoState::Locked);
}

#[test]
fn better_master_wins_and_a_silent_one_is_dropped() {
    let poor = Port::Master(Master::new(MasterConfig { priority1: 200, ..fast_master(0) }, pid(1)));
    let good = Port::Master(Master::new(MasterConfig { priority1: 100, ..fast_master(0) }, pid(3)));
    let slave = Port::Slave(Slave::new(fast_slave(0), pid(2)));
    let mut net = Net::new(vec![poor, slave, good], vec![(0, 0.0); 3], vec![5_000; 3], 0);
    net.run(3);
    let Port::Slave(s) = &net.ports[1] else { unreachable!() };
    assert_eq!(s.selected_master(), Some(pid(3)));

    // Only the poor master now: it takes over once the good one's Announces time out.
    let poor = Port::Master(Master::new(MasterConfig { priority1: 200, ..fast_master(0) }, pid(1)));
    let Port::Slave(s) = std::mem::replace(&mut net.ports[1], Port::Slave(Slave::new(fast_slave(0), pid(9)))) else {
        unreachable!()
    };
    let mut net2 = Net::new(vec![poor, Port::Slave(s)], vec![(0, 0.0); 2], vec![5_000; 2], 0);
    net2.start = T0 + 10_000_000_000;
    net2.run(3);
    let Port::Slave(s) = &net2.ports[1] else { unreachable!() };
    assert_eq!(s.selected_master(), Some(pid(1)));
    assert!(s.stats().master_changes >= 2);
}

#[test]
fn other_domains_are_ignored() {
    let master = Port::Master(Master::new(fast_master(5), pid(1)));
    let slave = Port::Slave(Slave::new(fast_slave(0), pid(2)));
    let mut net = Net::new(vec![master, slave], vec![(0, 0.0); 2], vec![5_000; 2], 0);
    net.run(3);
    let Port::Slave(s) = &net.ports[1] else { unreachable!() };
    assert_eq!(s.state(), SlaveState::Listening);
    assert!(net.samples.is_empty());
}

#[test]
fn steering_is_opt_in() {
    let master = Port::Master(Master::new(fast_master(0), pid(1)));
    let cfg = SlaveConfig { adjust_clock: true, ..fast_slave(0) };
    let slave = Port::Slave(Slave::new(cfg, pid(2)));
    let mut net = Net::new(vec![master, slave], vec![(0, 0.0), (100_000, 0.0)], vec![5_000; 2], 0);
    net.run(3);
    assert!(net.actions_seen.iter().any(|a| matches!(a, Action::StepClock { offset_ns: -100_000 })));
    assert!(net.actions_seen.iter().any(|a| matches!(a, Action::SetFrequency { .. })));
}

#[test]
fn master_answers_delay_req_and_follows_up_its_sync() {
    let mut m = Master::new(fast_master(0), pid(1));
    let start = m.start();
    assert_eq!(start.len(), 2);
    let sync = m.handle_timer(Timer::Sync, 1_000_000_000);
    let Some(Action::SendEvent { tag, data }) = sync.first() else { panic!("{sync:?}") };
    let parsed = crate::message::Message::parse(data).unwrap();
    assert!(parsed.header.flags.two_step() && parsed.header.flags.ptp_timescale());
    assert!(parsed.header.flags.utc_offset_valid());
    assert!(!parsed.header.flags.has(crate::message::Flags::TIME_TRACEABLE));
    let fup = m.handle_tx_timestamp(*tag, 1_000_000_500);
    let Some(Action::SendGeneral { data }) = fup.first() else { panic!("{fup:?}") };
    let parsed = crate::message::Message::parse(data).unwrap();
    let crate::message::Body::FollowUp { precise_origin } = parsed.body else { panic!() };
    assert_eq!(precise_origin.total_ns(), 38_000_000_500, "UTC + 37 s");
    // A stale timestamp sends nothing.
    assert!(m.handle_tx_timestamp(*tag, 5).is_empty());

    let ann = m.handle_timer(Timer::Announce, 2_000_000_000);
    let Some(Action::SendGeneral { data }) = ann.first() else { panic!() };
    let crate::message::Body::Announce(a) = crate::message::Message::parse(data).unwrap().body else { panic!() };
    assert_eq!(a.current_utc_offset, 37);
    assert_eq!(data.len(), 64);
}
