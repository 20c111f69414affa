//! The simulated Net F/T box as a box is, over real sockets: its settings page over HTTP gives the
//! calibration, units and ranges the sensor node takes (and judges saturation against), it streams at
//! its rate whether or not an FRI remote paces the cell, packs buffered mode's records as the box's
//! buffer size says, biases on the reading of the moment, and a Net F/T client no one here wrote
//! (`pynetft`, from PyPI) reads its calibration and its stream. The `ft_sensor` process takes the box's
//! calibration and refuses one copied by hand that differs from it.

#[allow(dead_code)]
mod common;

use std::net::{SocketAddr, UdpSocket};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use softcontact_nodes::ft_sensor::calibration::{fetch_settings, resolve};
use softcontact_nodes::ft_sensor::{FtConfig, FtSensorNode, Params};
use softcontact_sim::{SimConfig, Simulator};
use softcontact_simcell::sim_arm::{Pacing, SimArmConfig, SimArmServer, Transducer};
use softcontact_wire::rdt::{Calibration, RECORD_SIZE, RdtCommand, Record, Request, Status};

struct Cell {
    rdt: SocketAddr,
    http: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Drop for Cell {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The simulated cell with `transducer`'s box on ephemeral ports, in real time, no FRI remote.
fn cell(transducer: Transducer, rdt_buffer: u32) -> Cell {
    let settings = transducer.settings(1000.0, rdt_buffer);
    let mut config = SimConfig::above_surface(softcontact_sim::sponge(), 5);
    config.sensor.calibration = settings.calibration().unwrap();
    let nobody = UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap();
    let mut server = SimArmServer::bind(
        Simulator::new(config).unwrap(),
        SimArmConfig {
            fri_bind: "127.0.0.1:0".parse().unwrap(),
            fri_remote: nobody,
            rdt_bind: "127.0.0.1:0".parse().unwrap(),
            http_bind: Some("127.0.0.1:0".parse().unwrap()),
            box_settings: settings,
            measurement_loss: 0.0,
            command_loss: 0.0,
            rdt_rate: 1000.0,
            pacing: Pacing::RealTime { answer_wait: std::time::Duration::from_millis(20) },
            seed: 5,
        },
    )
    .unwrap();
    let (rdt, http) = (server.rdt_addr().unwrap(), server.http_addr().unwrap());
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let thread = std::thread::spawn(move || {
        server.run(|_| !flag.load(Ordering::Relaxed)).unwrap();
    });
    Cell { rdt, http, stop, thread: Some(thread) }
}

fn client(box_addr: SocketAddr) -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    s.connect(box_addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
    s
}

fn request(s: &UdpSocket, command: RdtCommand, sample_count: u32) {
    s.send(&Request { command, sample_count }.encode()).unwrap();
}

#[test]
fn the_sensor_node_takes_each_boxs_calibration_over_http_and_judges_saturation_by_its_ranges() {
    for (transducer, product) in
        [(Transducer::Gamma, "Gamma"), (Transducer::Nano17, "Nano17"), (Transducer::Mini45, "Mini45")]
    {
        let cell = cell(transducer, 1);
        let page = fetch_settings(cell.http, Duration::from_secs(2)).unwrap();
        assert!(page.product.contains(product), "{page:?}");
        let (calibration, said) = resolve(&Params::default(), Some(&page)).unwrap();
        assert_eq!(calibration, transducer.settings(1000.0, 1).calibration().unwrap());
        eprintln!("{said}");
        // Records as the box counts them: Fz at 90 % and at 110 % of its range (N), Fx 200 N.
        let counts = |f: [f64; 6]| -> [i32; 6] {
            std::array::from_fn(|i| {
                let per = if i < 3 {
                    calibration.counts_per_force / calibration.force_unit
                } else {
                    calibration.counts_per_torque / calibration.torque_unit
                };
                (f[i] * per).round() as i32
            })
        };
        let mut node = FtSensorNode::new(FtConfig::lwr4(calibration)).unwrap();
        let mut judge = |seq: u32, f: [f64; 6]| {
            let r = Record { rdt_sequence: seq, ft_sequence: seq, status: Status(0), counts: counts(f) };
            let out = node.handle(&r.encode(), None).unwrap();
            assert!(out.fresh);
            out.saturated
        };
        let fz = calibration.range[2];
        assert!(!judge(0, [0.0, 0.0, 0.9 * fz, 0.0, 0.0, 0.0]), "{product}: 90 % of Fz's range");
        assert!(judge(1, [0.0, 0.0, 1.1 * fz, 0.0, 0.0, 0.0]), "{product}: 110 % of Fz's range");
        // 200 N across: beyond a Nano17's 25 N and a Gamma's 130 N, within a Mini45's 267 N.
        assert_eq!(judge(2, [200.0, 0.0, 0.0, 0.0, 0.0, 0.0]), transducer != Transducer::Mini45, "{product}: Fx 200 N");
        // A Nano17 torque of 0.3 N·m is beyond its 250 N·mm.
        assert_eq!(judge(3, [0.0, 0.0, 0.0, 0.3, 0.0, 0.0]), transducer == Transducer::Nano17, "{product}: Tx 0.3 N·m");
    }
}

#[test]
fn a_wrong_path_or_no_box_is_an_error_that_says_where() {
    let cell = cell(Transducer::Gamma, 1);
    let nowhere = UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap();
    let e = fetch_settings(nowhere, Duration::from_millis(500)).unwrap_err().to_string();
    assert!(e.contains(&nowhere.to_string()), "{e}");
    // A server that sends the client elsewhere for the page: the calibration comes from the box or not
    // at all.
    let redirecting = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let (addr, page) = (redirecting.local_addr().unwrap(), cell.http);
    std::thread::spawn(move || {
        use std::io::{Read, Write};
        if let Ok((mut c, _)) = redirecting.accept() {
            let mut buf = [0u8; 1024];
            let _ = c.read(&mut buf);
            let answer =
                format!("HTTP/1.1 302 Found\r\nLocation: http://{page}/netftapi2.xml\r\nContent-Length: 0\r\n\r\n");
            let _ = c.write_all(answer.as_bytes());
        }
    });
    assert!(fetch_settings(addr, Duration::from_millis(500)).is_err(), "a redirect is not the box's page");
    // The box's RDT port speaks no HTTP; its web server answers 404 anywhere but the page.
    let rdt_http = SocketAddr::new(cell.rdt.ip(), cell.rdt.port());
    assert!(fetch_settings(rdt_http, Duration::from_millis(300)).is_err());
}

#[test]
fn the_box_streams_1_khz_without_an_fri_remote_and_packs_buffered_records() {
    let cell = cell(Transducer::Gamma, 4);
    let s = client(cell.rdt);
    let mut buf = [0u8; 2048];
    // Real-time mode: one record a datagram, counted over 2 s after a settling 0.2 s.
    request(&s, RdtCommand::StartRealTime, 0);
    let settle = Instant::now() + Duration::from_millis(200);
    while Instant::now() < settle {
        let _ = s.recv(&mut buf);
    }
    let (start, mut records) = (Instant::now(), 0usize);
    while start.elapsed() < Duration::from_secs(2) {
        let n = s.recv(&mut buf).unwrap();
        assert_eq!(n, RECORD_SIZE);
        records += 1;
    }
    let rate = records as f64 / start.elapsed().as_secs_f64();
    eprintln!("real-time mode: {rate:.1} records/s");
    assert!((980.0..=1020.0).contains(&rate), "1000 ± 20 Hz, not {rate:.1}");
    // Buffered mode: 4 records a datagram, consecutive, 100 records asked for.
    request(&s, RdtCommand::Stop, 0);
    std::thread::sleep(Duration::from_millis(50));
    while s.recv(&mut buf).is_ok() {}
    request(&s, RdtCommand::StartBuffered, 100);
    let mut sequences = Vec::new();
    while let Ok(n) = s.recv(&mut buf) {
        assert_eq!(n, 4 * RECORD_SIZE, "a buffered datagram holds the box's buffer size of records");
        for chunk in buf[..n].chunks(RECORD_SIZE) {
            sequences.push(Record::decode(chunk).unwrap().rdt_sequence);
        }
    }
    assert_eq!(sequences, (0..100).collect::<Vec<u32>>(), "100 records, in order, from 0");
}

#[test]
fn a_bias_request_before_streaming_zeroes_the_reading_of_that_moment() {
    let cell = cell(Transducer::Gamma, 1);
    let s = client(cell.rdt);
    let mut buf = [0u8; 64];
    let calibration = Calibration::gamma_si_130_10();
    let mean_fz = |s: &UdpSocket, buf: &mut [u8; 64]| {
        request(s, RdtCommand::StartRealTime, 200);
        let mut fz = Vec::new();
        while let Ok(n) = s.recv(buf) {
            fz.push(calibration.to_si(&Record::decode(&buf[..n]).unwrap().counts)[2]);
        }
        fz.iter().sum::<f64>() / fz.len().max(1) as f64
    };
    let before = mean_fz(&s, &mut buf);
    request(&s, RdtCommand::SetBias, 0);
    std::thread::sleep(Duration::from_millis(20));
    let after = mean_fz(&s, &mut buf);
    eprintln!("Fz before the bias {before:.3} N, after {after:.3} N");
    assert!(before.abs() > 2.0, "the hand's weight and the box's offset show before: {before}");
    // One reading of the moment: its noise (0.05 N) stays, the 2.8 N goes.
    assert!(after.abs() < 0.25, "biased on the reading of the moment: {after}");
}

#[test]
fn pynetft_reads_the_simulated_boxs_calibration_and_stream() {
    let python = std::env::var("SOFTCONTACT_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/netft_peer.py");
    for transducer in [Transducer::Mini45, Transducer::Nano17] {
        let cell = cell(transducer, 1);
        let out = std::process::Command::new(&python)
            .args([script, &cell.rdt.ip().to_string(), &cell.rdt.port().to_string(), &cell.http.port().to_string()])
            .output()
            .expect("python runs");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "pynetft peer failed:\n{text}\n{}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_str(text.trim()).unwrap();
        eprintln!("pynetft on the {transducer:?} box: {v}");
        let page = transducer.settings(1000.0, 1);
        assert!(v["product"].as_str().unwrap().contains(&page.product), "{v}");
        assert_eq!(v["counts_per_force"].as_f64().unwrap(), page.counts_per_force);
        assert_eq!(v["counts_per_torque"].as_f64().unwrap(), page.counts_per_torque);
        assert_eq!(v["force_unit"].as_str().unwrap(), page.force_unit);
        assert!(v["samples"].as_u64().unwrap() >= 200, "{v}");
        // pynetft's force in the box's unit, in N: the hand (the URDF's load) hangs on the sensor, plus the
        // simulated box's offset of about 1 N.
        let newtons = page.calibration().unwrap().force_unit;
        let force = v["mean_force"].as_array().unwrap().iter().map(|f| f.as_f64().unwrap() * newtons);
        let magnitude = force.map(|f| f * f).sum::<f64>().sqrt();
        let weight = softcontact_dynamics::lwr4::tool_load().mass * 9.81;
        assert!((magnitude - weight).abs() < 1.5, "|F| {magnitude:.2} N, the hand weighs {weight:.2} N");
        // pynetft's own conversion of the counts it was sent agrees with the box's page.
        assert!(v["conversion_error"].as_f64().unwrap() < 1e-9, "{v}");
    }
}

/// `ft_sensor` against a box, for 1.5 s: its exit status and its log.
fn ft_sensor_against(cell: &Cell, extra: &[&str]) -> (std::process::ExitStatus, String) {
    let (sensor, http) = (format!("sensor:={}", cell.rdt), format!("http_port:={}", cell.http.port()));
    let mut child = Command::new(env!("CARGO_BIN_EXE_ft_sensor"))
        .args(["-p", &sensor, "-p", &http, "-p", "tare_after:=-1"])
        .args(extra)
        .stdin(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1500));
    if child.try_wait().unwrap().is_none() {
        common::signal(&[&child], libc::SIGINT);
    }
    let out = child.wait_with_output().unwrap();
    (out.status, String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn the_ft_sensor_process_streams_with_the_boxs_calibration_and_refuses_a_different_one_by_hand() {
    if std::env::var(common::INNER).is_err() {
        common::in_isolated_namespace(
            "the_ft_sensor_process_streams_with_the_boxs_calibration_and_refuses_a_different_one_by_hand",
        );
        return;
    }
    let cell = cell(Transducer::Nano17, 1);
    let (status, log) = ft_sensor_against(&cell, &[]);
    eprintln!("{log}");
    assert!(status.success(), "clean exit on SIGINT: {status:?}");
    assert!(log.contains("calibration from Net F/T Nano17 SI-25-0.25"), "the box's calibration is taken");
    let records = log.rsplit("records: ").next().and_then(|t| t.split(',').next()).and_then(|n| n.parse::<u64>().ok());
    assert!(records.is_some_and(|n| n > 500), "records flow: {records:?}");

    // The Gamma's counts per torque copied onto the Nano17's box: refused before the node joins the graph.
    let (status, log) = ft_sensor_against(&cell, &["-p", "counts_per_torque:=1000000"]);
    eprintln!("{log}");
    assert!(!status.success(), "refused: {status:?}");
    assert!(log.contains("counts_per_torque 1000000 (the box: cfgcpt 1000)") && log.contains("calibration_override"));
    assert!(!log.contains("ready"), "the node never started");
    // With calibration_override the parameters win, and the node says so.
    let (status, log) =
        ft_sensor_against(&cell, &["-p", "counts_per_torque:=1000000", "-p", "calibration_override:=true"]);
    assert!(status.success() && log.contains("calibration_override: the parameters"), "{log}");
}
