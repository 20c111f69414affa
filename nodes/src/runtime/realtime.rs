//! How the thread that answers the KRC asks for the CPU. The KRC wants an answer within its cycle; on a
//! machine busy with other work at the same priority the answering thread must run as soon as a
//! datagram arrives. On the robot give the process a real-time priority (`chrt -f 80`, see
//! launch-scripts/README.md): then it always does. Without one, the thread asks Linux's fair scheduler for
//! a short time slice (`sched_setattr`, allowed to any user): under EEVDF (Linux 6.6 and later) a task
//! with a shorter slice gets an earlier deadline and so may preempt a busy neighbour when it wakes — but
//! only while it is eligible, i.e. has not had more than its share of the CPU. Measured, the slice alone
//! changed little; what keeps the thread answering under a busy neighbour is a share of its own: the
//! launch script gives the 1 kHz path's processes sessions of their own, which Linux's autogroup scheduling
//! serves before it splits their share between threads (launch-scripts/README.md, "Under load").

use std::time::Duration;

/// The slice the FRI thread asks for: the shortest the kernel grants.
pub const FRI_SLICE: Duration = Duration::from_micros(100);

/// Asks for `slice` for the calling thread, unless it already runs under a real-time policy (which
/// it keeps). Returns what the thread runs with, for the log.
pub fn request_short_slice(slice: Duration) -> std::io::Result<String> {
    // SAFETY: sched_getscheduler and getpriority only read the calling thread's scheduling state.
    let policy = unsafe { libc::sched_getscheduler(0) };
    if policy == libc::SCHED_FIFO || policy == libc::SCHED_RR {
        return Ok(format!("real-time policy {policy} kept"));
    }
    // getpriority returns the nice value; -1 is a valid one, so errno tells an error apart.
    let nice = unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) };
    let attr = libc::sched_attr {
        size: std::mem::size_of::<libc::sched_attr>() as u32,
        sched_policy: libc::SCHED_OTHER as u32,
        sched_flags: 0,
        sched_nice: nice,
        sched_priority: 0,
        sched_runtime: slice.as_nanos() as u64,
        sched_deadline: 0,
        sched_period: 0,
    };
    // SAFETY: a valid, fully initialised sched_attr of the size it states, for the calling thread (0).
    let r = unsafe { libc::syscall(libc::SYS_sched_setattr, 0, &attr as *const libc::sched_attr, 0u32) };
    if r != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(format!("fair scheduling, nice {nice}, slice {} us", slice.as_micros()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thread_gets_the_slice_it_asks_for() {
        std::thread::spawn(|| {
            let said = request_short_slice(FRI_SLICE).unwrap();
            assert!(said.contains("slice 100 us"), "{said}");
            // Read back: the kernel keeps the requested runtime for a fair task.
            let mut attr = std::mem::MaybeUninit::<libc::sched_attr>::zeroed();
            let size = std::mem::size_of::<libc::sched_attr>() as u32;
            // SAFETY: a buffer of `size` bytes for the calling thread's attributes.
            let r = unsafe { libc::syscall(libc::SYS_sched_getattr, 0, attr.as_mut_ptr(), size, 0u32) };
            assert_eq!(r, 0, "{}", std::io::Error::last_os_error());
            let attr = unsafe { attr.assume_init() };
            assert_eq!(attr.sched_policy, libc::SCHED_OTHER as u32);
            assert_eq!(attr.sched_runtime, 100_000);
        })
        .join()
        .unwrap();
    }
}
