//! The `sim_arm` process against the product's FRI driver over real UDP on loopback: the simulated KRC
//! serves the driver as the real one does, and with the gravity torque commanded the arm stays put.

use std::time::Duration;

use softcontact_dynamics::lwr4;
use softcontact_nodes::lwr_driver::{DriverOutput, LwrDriver, Params as DriverParams};
use softcontact_nodes::runtime::udp::FriClient;
use softcontact_wire::fri::InterfaceState;

#[test]
fn the_sim_arm_process_serves_fri_to_the_driver() {
    let model = lwr4::model();
    let mut data = model.data();
    let mut client = FriClient::bind("127.0.0.1:0".parse().unwrap(), LwrDriver::new(DriverParams::default())).unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_sim_arm"))
        .args(["-p", &format!("fri_remote:={}", client.local_addr().unwrap())])
        .args([
            "-p",
            "rdt_bind:=127.0.0.1:0",
            "-p",
            "http_bind:=127.0.0.1:0",
            "-p",
            "surface:=none",
            "-p",
            "seconds:=1.2",
        ])
        .spawn()
        .unwrap();
    let mut outputs: Vec<DriverOutput> = Vec::new();
    while let Some(out) = client.cycle(Duration::from_millis(200)).unwrap() {
        let gravity = model.gravity_torques(&mut data, &out.q);
        client.driver.set_command(gravity.as_slice()).unwrap();
        outputs.push(out);
    }
    assert!(child.wait().unwrap().success());
    let commanding: Vec<&DriverOutput> = outputs.iter().filter(|o| o.state == InterfaceState::Command).collect();
    assert!(commanding.len() > 700, "{} of {} outputs in command mode", commanding.len(), outputs.len());
    let q0 = commanding[0].q;
    let drift = outputs.last().unwrap().q.iter().zip(&q0).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(drift < 1e-4, "drift {drift} rad");
}
