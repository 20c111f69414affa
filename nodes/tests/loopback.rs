//! The driver and F/T nodes against the simulated cell over real UDP sockets on loopback, paced in real
//! time. The cell runs in a thread (its truth is what the tests compare against) or as the `sim_arm`
//! process (its own test is in simcell/tests/sim_arm.rs). Real-time tests run one at a time: two 1 kHz loops per test on a 2-core machine is enough.

use std::net::SocketAddr;
use std::sync::mpsc;
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

use nalgebra::{UnitQuaternion, Vector3};
use softcontact_dynamics::{Axes, lwr4};
use softcontact_nodes::ft_sensor::{FtConfig, FtSensorNode};
use softcontact_nodes::lwr_driver::{DriverOutput, LwrDriver, Params as DriverParams};
use softcontact_nodes::runtime::udp::{FriClient, RdtClient};
use softcontact_sim::{FtSensorConfig, SimConfig, Simulator};
use softcontact_simcell::sim_arm::{SimArmConfig, SimArmServer, SimArmStats};
use softcontact_wire::fri::InterfaceState;

static REAL_TIME: Mutex<()> = Mutex::new(());

fn one_at_a_time() -> MutexGuard<'static, ()> {
    REAL_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

/// What the simulator's truth looks like after a cycle.
#[derive(Debug, Clone)]
struct Truth {
    q: [f64; 7],
    dq: [f64; 7],
    state: InterfaceState,
    normal_force: f64,
    applied: [f64; 7],
}

/// Starts the cell in a thread for `cycles`, sending the truth of every cycle; its KRC waits 20 ms for an
/// answer (sim_arm's default).
fn start_cell(
    config: SimConfig,
    driver: SocketAddr,
    loss_each_way: f64,
    cycles: u64,
) -> (SocketAddr, mpsc::Receiver<Truth>, std::thread::JoinHandle<SimArmStats>) {
    start_cell_waiting(config, driver, loss_each_way, Duration::from_millis(20), cycles)
}

fn start_cell_waiting(
    config: SimConfig,
    driver: SocketAddr,
    loss_each_way: f64,
    answer_wait: Duration,
    cycles: u64,
) -> (SocketAddr, mpsc::Receiver<Truth>, std::thread::JoinHandle<SimArmStats>) {
    let sim = Simulator::new(config).unwrap();
    let mut server = SimArmServer::bind(
        sim,
        SimArmConfig {
            fri_bind: "127.0.0.1:0".parse().unwrap(),
            fri_remote: driver,
            rdt_bind: "127.0.0.1:0".parse().unwrap(),
            http_bind: None,
            box_settings: softcontact_simcell::sim_arm::Transducer::Gamma.settings(1000.0, 1),
            measurement_loss: loss_each_way,
            command_loss: loss_each_way,
            rdt_rate: 1000.0,
            pacing: softcontact_simcell::sim_arm::Pacing::RealTime { answer_wait },
            seed: 3,
        },
    )
    .unwrap();
    let rdt = server.rdt_addr().unwrap();
    let (tx, rx) = mpsc::channel();
    let handle = std::thread::spawn(move || {
        let mut n = 0;
        server
            .run(|sim| {
                n += 1;
                let _ = tx.send(Truth {
                    q: *sim.q(),
                    dq: *sim.dq(),
                    state: sim.krc.state(),
                    normal_force: sim.contact().normal_force,
                    applied: *sim.applied_torque(),
                });
                n < cycles
            })
            .unwrap()
    });
    (rdt, rx, handle)
}

fn gravity(q: &[f64; 7]) -> [f64; 7] {
    thread_local! {
        static MODEL: (softcontact_dynamics::Model, std::cell::RefCell<softcontact_dynamics::Data>) = {
            let m = lwr4::model();
            let d = std::cell::RefCell::new(m.data());
            (m, d)
        };
    }
    MODEL.with(|(model, data)| model.gravity_torques(&mut data.borrow_mut(), q).as_slice().try_into().unwrap())
}

/// Runs the driver until the cell stops sending, calling `control` on every output to set the next
/// command (the controller's place in the graph).
fn drive(client: &mut FriClient, mut control: impl FnMut(&DriverOutput) -> Option<[f64; 7]>) -> Vec<DriverOutput> {
    let mut outputs = Vec::new();
    while let Some(out) = client.cycle(Duration::from_millis(200)).unwrap() {
        if let Some(tau) = control(&out) {
            client.driver.set_command(&tau).unwrap();
        }
        outputs.push(out);
    }
    outputs
}

fn free_arm() -> SimConfig {
    SimConfig { surface: None, ..SimConfig::above_surface(softcontact_sim::sponge(), 1) }
}

#[test]
fn driver_and_sim_hold_the_arm_still_with_gravity_compensated() {
    let _rt = one_at_a_time();
    let mut client = FriClient::bind("127.0.0.1:0".parse().unwrap(), LwrDriver::new(DriverParams::default())).unwrap();
    let (_, truth, cell) = start_cell(free_arm(), client.local_addr().unwrap(), 0.0, 1500);
    // The controller commands exactly the gravity torque: the arm must not move.
    let outputs = drive(&mut client, |out| Some(gravity(&out.q)));
    let stats = cell.join().unwrap();
    let truth: Vec<Truth> = truth.try_iter().collect();
    let commanding = outputs.iter().filter(|o| o.state == InterfaceState::Command).count();
    assert!(commanding > 1000, "command mode reached and kept: {commanding} of {} cycles", outputs.len());
    let first = truth.iter().position(|t| t.state == InterfaceState::Command).unwrap();
    let drift = truth[first..]
        .iter()
        .flat_map(|t| t.q.iter().zip(&truth[first].q).map(|(a, b)| (a - b).abs()))
        .fold(0.0, f64::max);
    assert!(drift < 1e-4, "the arm drifted {drift} rad");
    assert_eq!(truth.last().unwrap().state, InterfaceState::Command);
    assert_eq!(client.driver.counters.malformed, 0);
    eprintln!("hold: driver {:?}, cell {stats:?}", client.driver.counters);
}

/// A remote that answers one measurement 12 ms late (a host without real-time scheduling): a KRC that
/// waits 0.9 of its cycle misses 11 cycles in a row and leaves command mode, brakes on; one told to wait
/// 20 ms pauses the arm for that answer, counts it late and keeps commanding.
#[test]
fn a_12_ms_late_answer_ends_command_mode_on_a_krc_waiting_0_9_ms_and_is_waited_for_with_answer_wait_20_ms() {
    let _rt = one_at_a_time();
    for (answer_wait, keeps_commanding) in [(Duration::ZERO, false), (Duration::from_millis(20), true)] {
        let mut client =
            FriClient::bind("127.0.0.1:0".parse().unwrap(), LwrDriver::new(DriverParams::default())).unwrap();
        let (_, truth, cell) = start_cell_waiting(free_arm(), client.local_addr().unwrap(), 0.0, answer_wait, 1500);
        let mut commanding = 0;
        let mut stalled = false;
        while let Some(_out) = client
            .cycle_with(Duration::from_millis(200), |driver, out| {
                commanding += usize::from(out.state == InterfaceState::Command);
                if commanding == 300 && !stalled {
                    stalled = true;
                    std::thread::sleep(Duration::from_millis(12));
                }
                driver.set_command(&gravity(&out.q)).unwrap();
            })
            .unwrap()
        {}
        let stats = cell.join().unwrap();
        let truth: Vec<Truth> = truth.try_iter().collect();
        let first = truth.iter().position(|t| t.state == InterfaceState::Command).expect("command mode reached");
        let left = truth[first..].iter().any(|t| t.state != InterfaceState::Command);
        assert!(stalled, "the remote stalled once");
        assert_eq!(!left, keeps_commanding, "answer_wait {answer_wait:?}: {stats:?}");
        if keeps_commanding {
            assert!(stats.late_answers >= 1, "the late answer counted: {stats:?}");
        }
    }
}

/// A constant torque on the wrist, through the driver and the KRC, accelerates it as M⁻¹τ predicts.
#[test]
fn a_constant_torque_moves_the_arm_as_the_dynamics_predict() {
    let _rt = one_at_a_time();
    let mut client = FriClient::bind("127.0.0.1:0".parse().unwrap(), LwrDriver::new(DriverParams::default())).unwrap();
    let (_, truth, cell) = start_cell(free_arm(), client.local_addr().unwrap(), 0.0, 1200);
    let extra = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.004];
    let mut commanding = 0;
    drive(&mut client, |out| {
        commanding += usize::from(out.state == InterfaceState::Command);
        let g = gravity(&out.q);
        // Hold still for 300 commanding cycles, then add the wrist torque.
        Some(std::array::from_fn(|i| g[i] + if commanding > 300 { extra[i] } else { 0.0 }))
    });
    cell.join().unwrap();
    let truth: Vec<Truth> = truth.try_iter().collect();
    let g_of = |t: &Truth| gravity(&t.q);
    let start =
        truth.iter().position(|t| (t.applied[6] - g_of(t)[6] - extra[6]).abs() < 2e-4).expect("the torque arrived");
    let end = (start + 400).min(truth.len() - 1);
    // Reference: the same constant torque from the same state, integrated finely.
    let model = lwr4::model();
    let mut data = model.data();
    let (mut q, mut dq) = (truth[start].q, truth[start].dq);
    let steps = (end - start) * 10;
    for _ in 0..steps {
        let g = gravity(&q);
        let tau: Vec<f64> = (0..7).map(|i| g[i] + extra[i]).collect();
        let ddq = model.forward_dynamics(&mut data, &q, &dq, &tau, None).unwrap().clone();
        for i in 0..7 {
            dq[i] += 1e-4 * ddq[i];
            q[i] += 1e-4 * dq[i];
        }
    }
    let moved = (truth[end].q[6] - truth[start].q[6]).abs();
    let err = (truth[end].q[6] - q[6]).abs();
    assert!(moved > 0.05, "the wrist turned {moved} rad");
    assert!(
        err < 0.03 * moved,
        "A6 moved {moved} rad, the dynamics predict {} (error {err})",
        (q[6] - truth[start].q[6]).abs()
    );
}

#[test]
fn the_ft_node_reports_the_simulated_contact_force() {
    let _rt = one_at_a_time();
    let mut config = SimConfig::above_surface(softcontact_sim::dice(), 4);
    config.sensor = FtSensorConfig::gamma(); // noise σ_z = 0.05 N and a bias the node must tare away
    let mut client = FriClient::bind("127.0.0.1:0".parse().unwrap(), LwrDriver::new(DriverParams::default())).unwrap();
    let (rdt, truth, cell) = start_cell(config, client.local_addr().unwrap(), 0.0, 4000);
    let ft_config = FtConfig {
        calibration: softcontact_wire::rdt::Calibration::gamma_si_130_10(),
        tool: lwr4::tool_load(),
        gravity: Vector3::new(0.0, 0.0, -9.81),
        low_pass: None,
        sample_rate: 1000.0,
    };
    let mut ft = RdtClient::connect(rdt, FtSensorNode::new(ft_config).unwrap()).unwrap();
    ft.start().unwrap();
    let model = lwr4::model();
    let mut data = model.data();
    let sensor_frame = model.frame_id(lwr4::FT_SENSOR_FRAME).unwrap();
    let tool = model.frame_id(lwr4::TOOL_FRAME).unwrap();
    let mut jac = nalgebra::Matrix6xX::zeros(7);
    let mut commanding = 0;
    let mut tared = false;
    let mut readings = Vec::new();
    while let Some(out) = client.cycle(Duration::from_millis(200)).unwrap() {
        commanding += usize::from(out.state == InterfaceState::Command);
        model.forward_kinematics(&mut data, &out.q);
        let orientation: UnitQuaternion<f64> = model.frame_pose(&data, sensor_frame).rotation;
        if let Some(reading) = ft.receive(Duration::from_micros(300), Some(&orientation)).unwrap() {
            if commanding == 200 && !tared {
                ft.node.tare(Some(&orientation)).unwrap();
                tared = true;
            }
            if commanding > 3000 {
                // The world-z component of the force on the hand: the sensor reads it in its own axes.
                let c = reading.compensated.unwrap();
                readings.push((orientation * Vector3::new(c[0], c[1], c[2])).z);
            }
        }
        // After 300 cycles in the air, press down with 40 N (through Jᵀ), joints damped.
        model.frame_jacobian(&data, tool, Axes::World, &mut jac);
        let push = if commanding > 300 { -40.0 } else { 0.0 };
        let f = jac.transpose() * nalgebra::Vector6::new(0.0, 0.0, push, 0.0, 0.0, 0.0);
        let g = gravity(&out.q);
        // Joint damping scaled to each joint's inertia: with the loop's one-cycle delay a damper is
        // stable only while c·dt/M_ii stays well below 1 (the wrist has M_77 ≈ 0.002 kg·m²).
        const DAMPING: [f64; 7] = [3.0, 3.0, 1.0, 1.0, 0.3, 0.1, 0.05];
        client.driver.set_command(&std::array::from_fn::<f64, 7, _>(|i| g[i] + f[i] - DAMPING[i] * out.dq[i])).unwrap();
    }
    ft.stop().unwrap();
    cell.join().unwrap();
    let truth: Vec<Truth> = truth.try_iter().collect();
    let force = truth.last().unwrap().normal_force;
    eprintln!(
        "ft: commanding {commanding}, readings {}, last truth {:?}, driver {:?}, ft {:?}",
        readings.len(),
        truth.last(),
        client.driver.counters,
        ft.node.counters
    );
    assert!((force - 40.0).abs() < 1.5, "the hand settled at {force} N");
    assert!(readings.len() > 500, "{} readings", readings.len());
    let mean = readings.iter().sum::<f64>() / readings.len() as f64;
    // Within the noise of a mean of this many readings (σ/√n ≈ 0.002 N), the single-reading tare
    // (σ ≈ 0.05 N) and the force's own settling.
    assert!((mean - force).abs() < 0.25, "F/T node reads {mean} N up, the surface pushes {force} N");
    assert_eq!(ft.node.counters.malformed, 0);
}

#[test]
fn five_percent_packet_loss_is_survived_and_counted() {
    let _rt = one_at_a_time();
    let mut client = FriClient::bind("127.0.0.1:0".parse().unwrap(), LwrDriver::new(DriverParams::default())).unwrap();
    // 5 % of all FRI datagrams: 5 % of the measurements and 5 % of the commands.
    let (_, truth, cell) = start_cell(free_arm(), client.local_addr().unwrap(), 0.05, 2500);
    let outputs = drive(&mut client, |out| Some(gravity(&out.q)));
    let stats = cell.join().unwrap();
    eprintln!("loss: driver {:?}, cell {stats:?}", client.driver.counters);
    let truth: Vec<Truth> = truth.try_iter().collect();
    let lost = client.driver.counters.lost as f64;
    assert!(
        (stats.measurements_dropped as f64 - lost).abs() <= 2.0,
        "driver counted {lost} lost, the cell dropped {}",
        stats.measurements_dropped
    );
    // Loss starts once the KRC commands (it would not enter command mode over a lossy link).
    let lossy_cycles = truth.iter().filter(|t| t.state == InterfaceState::Command).count() as f64;
    assert!(lossy_cycles > 2000.0, "the KRC kept command mode through the loss: {lossy_cycles} cycles");
    let all_lost = (stats.measurements_dropped + stats.commands_dropped) as f64;
    assert!(
        (0.035..0.065).contains(&(all_lost / (2.0 * lossy_cycles))),
        "≈ 5 % of datagrams lost: {all_lost} of {}",
        2.0 * lossy_cycles
    );
    let commanding = outputs.iter().filter(|o| o.state == InterfaceState::Command).count();
    assert!(commanding as f64 > 0.9 * lossy_cycles, "driver saw command mode: {commanding}");
    let first = truth.iter().position(|t| t.state == InterfaceState::Command).unwrap();
    let drift = truth[first..]
        .iter()
        .flat_map(|t| t.q.iter().zip(&truth[first].q).map(|(a, b)| (a - b).abs()))
        .fold(0.0, f64::max);
    assert!(drift < 1e-3, "stable under loss: drift {drift} rad");
}

#[test]
fn malformed_datagrams_are_refused_and_counted() {
    let _rt = one_at_a_time();
    let mut client = FriClient::bind("127.0.0.1:0".parse().unwrap(), LwrDriver::new(DriverParams::default())).unwrap();
    let target = client.local_addr().unwrap();
    let (_, truth, cell) = start_cell(free_arm(), target, 0.0, 1200);
    let rogue = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut sent = 0;
    let outputs = drive(&mut client, |out| {
        if out.sequence % 50 == 0 {
            let junk: &[&[u8]] = &[b"hello", &[0u8; 916], &[0xFF; 376]];
            rogue.send_to(junk[sent % 3], target).unwrap();
            sent += 1;
        }
        Some(gravity(&out.q))
    });
    cell.join().unwrap();
    assert!(sent >= 20);
    // From another port of the KRC's address while the KRC talks: strangers, refused before decoding.
    assert_eq!(client.driver.counters.strangers, sent as u64, "every rogue datagram refused and counted");
    assert_eq!(client.driver.counters.sessions, 1, "the rogue port never took the session over");
    assert!(outputs.iter().filter(|o| o.state == InterfaceState::Command).count() > 800);
    assert_eq!(truth.try_iter().last().unwrap().state, InterfaceState::Command);
}

#[test]
fn a_stale_controller_makes_the_driver_hold_position() {
    let _rt = one_at_a_time();
    let mut client = FriClient::bind("127.0.0.1:0".parse().unwrap(), LwrDriver::new(DriverParams::default())).unwrap();
    let (_, truth, cell) = start_cell(free_arm(), client.local_addr().unwrap(), 0.0, 1500);
    let mut n = 0;
    // The controller commands a wrist torque, then goes silent after 500 cycles.
    let outputs = drive(&mut client, |out| {
        n += 1;
        let g = gravity(&out.q);
        (n < 500).then(|| std::array::from_fn(|i| g[i] + if i == 6 { 0.003 } else { 0.0 }))
    });
    cell.join().unwrap();
    let truth: Vec<Truth> = truth.try_iter().collect();
    assert!(outputs.last().unwrap().holding, "holding after the controller stopped");
    assert!(client.driver.counters.stale_cycles > 900);
    // Held: the wrist comes to rest.
    let last = truth.last().unwrap();
    assert!(last.dq.iter().all(|v| v.abs() < 0.01), "at rest: {:?}", last.dq);
    assert_eq!(last.state, InterfaceState::Command, "holding is done by the driver, the KRC stays in command mode");
}
