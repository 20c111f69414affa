//! What the tests that run node processes over real DDS or UDP share: they re-run themselves inside a
//! network namespace that has only loopback (docs/architecture.md, "The ROS 2 graph"), so that DDS stays on this machine, and
//! there start node processes that must not outlive the test.

use std::process::{Child, Command, Stdio};

/// Set in the re-run inside the namespace: the test then does its work instead of re-running itself.
pub const INNER: &str = "SOFTCONTACT_INSIDE_NETNS";

/// Runs the named test of this binary again, inside a fresh network namespace with only `lo` (in a user
/// namespace too, so that it needs no root).
pub fn in_isolated_namespace(test: &str) {
    in_isolated_namespace_with(test, &[]);
}

/// [`in_isolated_namespace`], the re-run with the environment variables `vars` set.
pub fn in_isolated_namespace_with(test: &str, vars: &[(&str, &std::ffi::OsStr)]) {
    let exe = std::env::current_exe().unwrap();
    let script = format!(
        "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && exec '{}' --exact {test} --nocapture --test-threads=1",
        exe.display()
    );
    let out = Command::new("unshare")
        .args(["--map-root-user", "--net", "sh", "-c", &script])
        .env(INNER, "1")
        .envs(vars.iter().copied())
        .output()
        .expect("unshare runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    eprintln!("{text}");
    assert!(out.status.success() && text.contains("1 passed"), "isolated run failed:\n{text}");
}

/// Child processes, killed and reaped on drop (also when the test panics).
pub struct Processes(pub Vec<Child>);

impl Drop for Processes {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

pub fn spawn(bin: &str, args: &[&str]) -> Child {
    Command::new(bin).args(args).stdin(Stdio::null()).spawn().unwrap_or_else(|e| panic!("{bin}: {e}"))
}

pub fn signal(children: &[&Child], sig: libc::c_int) {
    for c in children {
        // SAFETY: kill(2) on the pid of a child we have not waited for yet.
        assert_eq!(unsafe { libc::kill(c.id() as libc::pid_t, sig) }, 0, "kill {sig}");
    }
}

/// A node binary of the workspace, found beside this test's own (target/<profile>/): the simulated cell's
/// `sim_arm` is another package's binary, which `cargo test --workspace` builds with this one.
pub fn workspace_binary(name: &str) -> String {
    let exe = std::env::current_exe().unwrap();
    let path = exe.parent().and_then(std::path::Path::parent).unwrap().join(name);
    assert!(
        path.is_file(),
        "{} is not built: run the tests with `cargo test --workspace` (or build it: `cargo build -p softcontact-simcell`)",
        path.display()
    );
    path.display().to_string()
}
