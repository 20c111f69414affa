//! The F/T side of the safety issue over real UDP: the sensor node survives a box that is not up yet
//! (ICMP port unreachable: ECONNREFUSED on a connected socket), keeps asking it to stream, and streams
//! once it comes up; repeated and older records are not passed on as fresh. Once in-process (the
//! node's `RdtClient`), once with the real `ft_sensor` process in a loopback-only network namespace.

#[allow(dead_code)]
mod common;

use std::net::{SocketAddr, UdpSocket};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use common::{INNER, in_isolated_namespace, signal};
use nalgebra::Vector3;
use softcontact_dynamics::lwr4;
use softcontact_nodes::ft_sensor::{FtConfig, FtSensorNode};
use softcontact_nodes::runtime::udp::RdtClient;
use softcontact_wire::rdt::{Calibration, RdtCommand, Record, Request, Status};

/// The fake box serves no settings page: the node starts from the Gamma's calibration given by hand.
const CALIBRATION_BY_HAND: [&str; 12] = [
    "-p",
    "http_port:=0",
    "-p",
    "counts_per_force:=1000000",
    "-p",
    "counts_per_torque:=1000000",
    "-p",
    "force_unit:=N",
    "-p",
    "torque_unit:=Nm",
    "-p",
    "ranges:=[130, 130, 400, 10, 10, 10]",
];

/// A port on 127.0.0.1 that nothing listens on (bound, then closed).
fn closed_port() -> SocketAddr {
    UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap()
}

fn node() -> FtSensorNode {
    FtSensorNode::new(FtConfig {
        calibration: Calibration::gamma_si_130_10(),
        tool: lwr4::tool_load(),
        gravity: Vector3::new(0.0, 0.0, -9.81),
        low_pass: None,
        sample_rate: 1000.0,
    })
    .unwrap()
}

/// A Net F/T box at `addr`: on each start request it streams records at up to 1 kHz from sequence 0,
/// until stopped; `extra` sends, after every 100th record, a copy of it and one 50 records older
/// (what a misbehaving network or a replay would deliver). Returns the records sent.
fn fake_box(addr: SocketAddr, extra: bool, stop: Arc<AtomicBool>) -> JoinHandle<usize> {
    slow_box(addr, extra, Duration::ZERO, stop)
}

/// [`fake_box`] that begins a stream `answer_after` a start request (a busy box or network).
fn slow_box(addr: SocketAddr, extra: bool, answer_after: Duration, stop: Arc<AtomicBool>) -> JoinHandle<usize> {
    let socket = UdpSocket::bind(addr).unwrap();
    socket.set_read_timeout(Some(Duration::from_millis(1))).unwrap();
    std::thread::spawn(move || {
        let mut buf = [0u8; 64];
        let mut client: Option<SocketAddr> = None;
        let (mut seq, mut sent, mut begin) = (0u32, 0usize, Instant::now());
        let counts = Calibration::gamma_si_130_10().to_counts(&[0.1, 0.2, 1.5, 0.0, 0.0, 0.0]).0;
        let rec = |s: u32| Record { rdt_sequence: s, ft_sequence: s, status: Status(0), counts }.encode();
        while !stop.load(Ordering::Relaxed) {
            if let Ok((n, from)) = socket.recv_from(&mut buf) {
                match Request::decode(&buf[..n]).map(|r| r.command) {
                    Ok(RdtCommand::StartRealTime) => {
                        (client, seq, begin) = (Some(from), 0, Instant::now() + answer_after)
                    }
                    Ok(RdtCommand::Stop) => client = None,
                    _ => {}
                }
            }
            if let Some(to) = client.filter(|_| Instant::now() >= begin) {
                let _ = socket.send_to(&rec(seq), to);
                sent += 1;
                if extra && seq % 100 == 99 {
                    let _ = socket.send_to(&rec(seq), to);
                    let _ = socket.send_to(&rec(seq - 50), to);
                }
                seq += 1;
            }
        }
        sent
    })
}

#[test]
fn the_rdt_client_outlives_a_box_that_is_not_up_and_streams_once_it_is() {
    let addr = closed_port();
    let mut client = RdtClient::connect(addr, node()).unwrap();
    client.start().unwrap();
    // Nobody there: every receive ends without a record and without an error, for 1.5 s.
    let until = Instant::now() + Duration::from_millis(1500);
    while Instant::now() < until {
        assert!(client.receive(Duration::from_millis(10), None).unwrap().is_none());
    }
    let refused = client.node.counters.network_errors;
    assert!(refused >= 2, "the port unreachable errors are counted ({refused}), and the start repeated");
    // The box comes up; the client's periodic start request (every second) finds it.
    let stop = Arc::new(AtomicBool::new(false));
    let ft_box = fake_box(addr, true, stop.clone());
    let mut fresh = Vec::new();
    let until = Instant::now() + Duration::from_secs(5);
    while Instant::now() < until && fresh.len() < 500 {
        if let Some(out) = client.receive(Duration::from_millis(10), None).unwrap() {
            fresh.push(out.rdt_sequence);
        }
    }
    client.stop().unwrap();
    stop.store(true, Ordering::Relaxed);
    ft_box.join().unwrap();
    let c = client.node.counters;
    eprintln!("{c:?}");
    assert!(fresh.len() >= 500, "records flow once the box is up: {} of 500 within 5 s", fresh.len());
    assert!(fresh.windows(2).all(|w| w[1] > w[0]), "only fresh records, in order");
    assert!(c.duplicate >= 4 && c.out_of_order >= 4, "the box's repeats and old records are skipped: {c:?}");
    assert_eq!(c.lost, 0, "{c:?}");
}

/// A counter of the node's exit report (`FtCounters { records: 123, … }`).
fn counter(report: &str, name: &str) -> Option<u64> {
    let at = report.rfind(&format!("{name}: "))? + name.len() + 2;
    report[at..].split(|c: char| !c.is_ascii_digit()).next()?.parse().ok()
}

#[test]
fn the_ft_sensor_node_outlives_a_box_that_is_not_up_and_streams_once_it_is() {
    if std::env::var(INNER).is_err() {
        in_isolated_namespace("the_ft_sensor_node_outlives_a_box_that_is_not_up_and_streams_once_it_is");
        return;
    }
    let addr = closed_port();
    let mut child = Command::new(env!("CARGO_BIN_EXE_ft_sensor"))
        .args(["-p", &format!("sensor:={addr}"), "-p", "tare_after:=-1"])
        .args(CALIBRATION_BY_HAND)
        .stdin(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(2500));
    let early = child.try_wait().unwrap();
    if early.is_some() {
        let out = child.wait_with_output().unwrap();
        panic!("ft_sensor ended while the box was down: {early:?}\n{}", String::from_utf8_lossy(&out.stderr));
    }
    let stop = Arc::new(AtomicBool::new(false));
    let ft_box = fake_box(addr, false, stop.clone());
    std::thread::sleep(Duration::from_millis(3000));
    signal(&[&child], libc::SIGINT);
    let out = child.wait_with_output().unwrap();
    stop.store(true, Ordering::Relaxed);
    let sent = ft_box.join().unwrap();
    let report = String::from_utf8_lossy(&out.stderr);
    eprintln!("{report}");
    assert!(out.status.success(), "clean exit on SIGINT: {:?}", out.status);
    let records = counter(&report, "records").expect("exit report with counters");
    let errors = counter(&report, "network_errors").unwrap();
    assert!(errors >= 1, "the refused start requests are counted: {errors}");
    assert!(records >= 200 && records as usize <= sent, "records flow once the box is up: {records} of {sent}");
}

#[test]
fn an_ft_sensor_told_to_exit_after_a_silence_of_1_s_waits_for_a_box_that_answers_20_ms_late() {
    if std::env::var(INNER).is_err() {
        in_isolated_namespace(
            "an_ft_sensor_told_to_exit_after_a_silence_of_1_s_waits_for_a_box_that_answers_20_ms_late",
        );
        return;
    }
    let addr = closed_port();
    let mut child = Command::new(env!("CARGO_BIN_EXE_ft_sensor"))
        .args(["-p", &format!("sensor:={addr}"), "-p", "tare_after:=-1", "-p", "exit_after_silence:=1"])
        .args(CALIBRATION_BY_HAND)
        .stdin(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The box comes up after the node's first start request, and streams 20 ms after each request.
    std::thread::sleep(Duration::from_millis(300));
    let stop = Arc::new(AtomicBool::new(false));
    let ft_box = slow_box(addr, false, Duration::from_millis(20), stop.clone());
    std::thread::sleep(Duration::from_millis(2200));
    let early = child.try_wait().unwrap();
    signal(&[&child], libc::SIGINT);
    let out = child.wait_with_output().unwrap();
    stop.store(true, Ordering::Relaxed);
    let sent = ft_box.join().unwrap();
    let report = String::from_utf8_lossy(&out.stderr);
    eprintln!("{report}");
    assert!(early.is_none(), "ft_sensor gave up on a box that answers late: {early:?}");
    let records = counter(&report, "records").expect("exit report with counters");
    assert!(records >= 100 && records as usize <= sent, "records flow once the box answers: {records} of {sent}");
}
