//! The 1 kHz path allocates nothing after start-up — the controller's tick, the controller node's
//! policy around it, the driver's hand-over: counted by a global allocator that counts this thread's
//! allocations while a flag is set.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use nalgebra::Vector3;
use softcontact_nodes::deformation_controller::{
    ControllerConfig, ControllerNode, DeformationController, JointSample, Params, Reply,
};

struct Counting;

// Per thread: the tests run in parallel, and one of them allocates on purpose.
thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    if COUNTING.with(|c| c.get()) {
        ALLOCATIONS.with(|a| a.set(a.get() + 1));
    }
}

fn allocations() -> u64 {
    ALLOCATIONS.with(|a| a.get())
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_controller_tick_does_not_allocate() {
    let mut controller =
        DeformationController::new(ControllerConfig::lwr4(250.0, 0.06), softcontact_sim::sponge()).unwrap();
    let mut q = softcontact_sim::DEFAULT_Q;
    let dq = [0.0, 0.01, 0.0, -0.02, 0.0, 0.01, 0.0];
    // Start-up and contact: the first ticks may allocate (nothing is preallocated before the first state).
    let mut time = 100.0;
    for i in 0..600 {
        q[1] += 1e-5;
        time += 1e-3;
        let f = if i > 300 { (i - 300) as f64 * 0.1 } else { 0.0 };
        controller.tick(time, &q, &dq, f, &Vector3::new(0.0, 0.0, f)).unwrap();
    }
    controller.command_force(120.0, 2.0).unwrap();
    COUNTING.with(|c| c.set(true));
    let mut sum = 0.0;
    for i in 0..2000 {
        q[3] -= 1e-6;
        time += 1e-3;
        let f = 30.0 + i as f64 * 0.01;
        let (tau, state) = controller.tick(time, &q, &dq, f, &Vector3::new(0.0, 0.0, f)).unwrap();
        sum += tau[1] + state.z_cmd;
    }
    COUNTING.with(|c| c.set(false));
    assert!(sum.is_finite());
    assert_eq!(allocations(), 0, "allocations in 2000 ticks in contact");
    // Positive control: the counter does see an allocation on this thread.
    COUNTING.with(|c| c.set(true));
    let probe: Vec<u64> = Vec::with_capacity(std::hint::black_box(16));
    COUNTING.with(|c| c.set(false));
    drop(std::hint::black_box(probe));
    assert_eq!(allocations(), 1, "the counter counts");
}

/// Through an augmented model (relaxation branches, hysteresis): the effects' states advance every
/// tick, and after the move the hold is re-solved every tick — without an allocation.
#[test]
fn the_controller_tick_through_an_augmented_model_does_not_allocate() {
    let model = softcontact_sim::lab_sponge();
    assert!(!model.effects.is_empty());
    let mut controller = DeformationController::new(ControllerConfig::lwr4(250.0, 0.06), model).unwrap();
    let mut q = softcontact_sim::DEFAULT_Q;
    let dq = [0.0, 0.01, 0.0, -0.02, 0.0, 0.01, 0.0];
    let mut time = 100.0;
    for i in 0..600 {
        q[1] += 1e-5;
        time += 1e-3;
        let f = if i > 300 { (i - 300) as f64 * 0.1 } else { 0.0 };
        controller.tick(time, &q, &dq, f, &Vector3::new(0.0, 0.0, f)).unwrap();
    }
    controller.command_force(120.0, 1.0).unwrap();
    COUNTING.with(|c| c.set(true));
    let mut sum = 0.0;
    // The 1 s move and 2 s of the hold.
    for i in 0..3000 {
        q[3] -= 1e-6;
        time += 1e-3;
        let f = 30.0 + i as f64 * 0.01;
        let (tau, state) = controller.tick(time, &q, &dq, f, &Vector3::new(0.0, 0.0, f)).unwrap();
        sum += tau[1] + state.z_cmd;
    }
    COUNTING.with(|c| c.set(false));
    assert!(sum.is_finite());
    assert_eq!(allocations(), 0, "allocations in 3000 ticks through the augmented model");
}

/// The in-process hand-over on the FRI thread allocates nothing: the driver reads a measurement, the
/// torque for it is handed over, and the driver answers with it.
#[test]
fn the_driver_hand_over_does_not_allocate() {
    use softcontact_nodes::lwr_driver::{LwrDriver, Params as DriverParams};
    let mut sim =
        softcontact_sim::Simulator::new(softcontact_sim::SimConfig::above_surface(softcontact_sim::sponge(), 3))
            .unwrap();
    // The KRC's measurements of 50 commanding cycles, made beforehand (a driver answers the KRC into
    // command mode; encoding allocates).
    let mut warm = LwrDriver::new(DriverParams::default());
    let mut datagrams: Vec<[u8; 916]> = Vec::new();
    for _ in 0..10_000 {
        let m = sim.measurement();
        let bytes = m.encode();
        if m.intf.state == softcontact_wire::fri::InterfaceState::Command {
            datagrams.push(bytes);
        }
        let (reply, _) = warm.handle(&bytes).unwrap();
        sim.command(&reply);
        sim.step_cycle().unwrap();
        if datagrams.len() == 50 {
            break;
        }
    }
    assert_eq!(datagrams.len(), 50, "the KRC reached command mode");
    let mut driver = LwrDriver::new(DriverParams::default());
    let tau = [0.5, 20.0, 0.1, -8.0, 0.2, 1.0, 0.0];
    let mut sequence = 0u64;
    for d in &datagrams[..5] {
        let measured = driver.measure(d).unwrap();
        driver.set_command(&tau).unwrap();
        driver.answer(measured);
    }
    COUNTING.with(|c| c.set(true));
    for d in &datagrams[5..] {
        let measured = driver.measure(d).unwrap();
        driver.set_command(&tau).unwrap();
        let (reply, out) = driver.answer(measured);
        // The command path itself, not a hold.
        assert!(!out.holding && reply.add_jnt_trq.iter().any(|t| *t != 0.0));
        sequence += u64::from(reply.header.refl_seq);
    }
    COUNTING.with(|c| c.set(false));
    assert!(sequence > 0);
    assert_eq!(allocations(), 0, "allocations in 45 hand-overs");
}

/// The controller node's policy around the tick (freshness, sessions, the sensor's force into the world)
/// allocates nothing either: what the composed process runs on its FRI thread.
#[test]
fn the_controller_node_does_not_allocate() {
    let mut node = ControllerNode::from_params(&Params::default()).unwrap();
    let mut q = softcontact_sim::DEFAULT_Q;
    let dq = [0.0; 7];
    let mut step = |q: &[f64; 7], i: usize| {
        let t = 50.0 + i as f64 * 1e-3;
        node.on_force(t, Vector3::new(0.1, -0.2, 0.3), t);
        node.on_external_torque(t, &[0.1, -0.3, 0.0, 0.2, 0.0, 0.05, 0.0]);
        let js = JointSample { stamp: t, session: Some(1), commanding: true, q: *q, dq };
        node.on_joint_state(&js, t)
    };
    for i in 0..100 {
        assert!(matches!(step(&q, i).reply, Reply::Torque(_)));
    }
    COUNTING.with(|c| c.set(true));
    let mut torques = 0;
    for i in 100..1100 {
        q[0] += 1e-6;
        torques += usize::from(matches!(step(&q, i).reply, Reply::Torque(_)));
    }
    COUNTING.with(|c| c.set(false));
    assert_eq!(torques, 1000, "every joint state answered with a torque");
    assert_eq!(allocations(), 0, "allocations in 1000 steps of the controller node");
}
