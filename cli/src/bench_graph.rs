//! `softcontact bench graph`: what ROS 2 security costs the running graph. The simulated cell and the
//! nodes (`launch-scripts/sim.sh --isolated`, the sponge, the hand resting on it) run for a while plain and
//! then under ROS 2 security (`--secure`: authenticated, every topic encrypted, RTPS messages signed), in the
//! same run, alternating when repeated. Each run gives:
//!
//! - the FRI loop's answer: how long lwr_control took from the KRC's datagram in the kernel to its reply
//!   (its exit report: p50, p99, the share within 200 µs), and the simulated KRC's late answers;
//! - each process's CPU over the measured window (user + system time from `/proc/PID/stat`, in % of one
//!   core), after a settling time that covers discovery and, secure, the handshakes.
//!
//! The secure column needs a build with the `security` feature.

use std::path::Path;
use std::process::Command;

use anyhow::Context;

/// The graph's processes, as `launch.sh` starts them from the binaries' folder.
const PROCESSES: [&str; 3] = ["sim_arm", "lwr_control", "contact_estimator"];

/// One run's numbers.
#[derive(Debug, Clone, Default)]
struct Run {
    /// The FRI answer's latency: p50 and p99 in µs, and the share of cycles within 200 µs in %.
    p50_us: f64,
    p99_us: f64,
    within_200us: f64,
    /// The simulated KRC's answers that came after its deadline, of its cycles.
    late_answers: f64,
    cycles: f64,
    /// CPU of each of [`PROCESSES`] over the window, in % of one core.
    cpu: [f64; 3],
}

pub fn run(seconds: f64, settle: f64, reps: usize) -> anyhow::Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().context("the repository root")?;
    let script = root.join("launch-scripts/sim.sh");
    anyhow::ensure!(script.exists(), "bench graph needs the repository's {} (run from a checkout)", script.display());
    let modes: &[bool] = if cfg!(feature = "security") { &[false, true] } else { &[false] };
    if !cfg!(feature = "security") {
        eprintln!("bench graph: built without the `security` feature, so the plain graph only");
    }
    let mut runs: Vec<(bool, Run)> = Vec::new();
    for rep in 0..reps {
        for &secure in modes {
            let logs =
                std::env::temp_dir().join(format!("softcontact-bench-graph-{}-{rep}-{secure}", std::process::id()));
            let _ = std::fs::remove_dir_all(&logs);
            let measured = run_once(&script, &logs, secure, seconds, settle)
                .map_err(|e| anyhow::anyhow!("{e:#} (logs in {})", logs.display()))?;
            let _ = std::fs::remove_dir_all(&logs);
            runs.push((secure, measured));
        }
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "the graph over DDS (sim.sh --isolated, the sponge, the hand resting on it): {seconds} s measured after \
         {settle} s, {reps} run(s) each, median; {cores} cores"
    );
    let table = |secure: bool| -> Vec<(String, f64)> {
        let of_mode: Vec<Vec<(String, f64)>> =
            runs.iter().filter(|(s, _)| *s == secure).map(|(_, r)| r.rows()).collect();
        let Some(first) = of_mode.first() else { return Vec::new() };
        (0..first.len())
            .map(|i| {
                let mut v: Vec<f64> = of_mode.iter().map(|rows| rows[i].1).collect();
                v.sort_by(f64::total_cmp);
                (first[i].0.clone(), v[v.len() / 2])
            })
            .collect()
    };
    let (plain, secure) = (table(false), table(true));
    if secure.is_empty() {
        println!("  {:<34} {:>10}", "", "plain");
    } else {
        println!("  {:<34} {:>10} {:>10} {:>8}", "", "plain", "secure", "ratio");
    }
    for (i, (name, p)) in plain.iter().enumerate() {
        match secure.get(i) {
            Some((_, s)) => println!("  {name:<34} {p:>10.1} {s:>10.1} {:>8.2}", s / p),
            None => println!("  {name:<34} {p:>10.1}"),
        }
    }
    Ok(())
}

impl Run {
    /// The table's rows: what each number is, and its value.
    fn rows(&self) -> Vec<(String, f64)> {
        let mut rows = vec![
            ("FRI answer p50 [µs]".to_owned(), self.p50_us),
            ("FRI answer p99 [µs]".to_owned(), self.p99_us),
            ("FRI answers within 200 µs [%]".to_owned(), self.within_200us),
            ("KRC late answers [% of cycles]".to_owned(), 100.0 * self.late_answers / self.cycles.max(1.0)),
        ];
        for (name, cpu) in PROCESSES.iter().zip(self.cpu) {
            rows.push((format!("CPU {name} [% of a core]"), cpu));
        }
        rows.push(("CPU of the graph [% of a core]".to_owned(), self.cpu.iter().sum()));
        rows
    }
}

/// One graph run with the CPU sampled twice inside the namespace; its numbers from the samples and logs.
fn run_once(script: &Path, logs: &Path, secure: bool, seconds: f64, settle: f64) -> anyhow::Result<Run> {
    std::fs::create_dir_all(logs)?;
    // user + system clock ticks of each graph process, by its binary's name.
    let inside = r#"
        cpu() {
            for p in /proc/[0-9]*; do
                e=$(readlink "$p/exe" 2>/dev/null) || continue
                case "${e##*/}" in sim_arm|lwr_control|contact_estimator)
                    echo "${e##*/} $(cut -d' ' -f14,15 "$p/stat" 2>/dev/null)" ;;
                esac
            done
        }
        sleep "$2"; cpu > "$1/cpu0"; date +%s.%N > "$1/t0"
        sleep "$3"; cpu > "$1/cpu1"; date +%s.%N > "$1/t1"
    "#;
    let mut cmd = Command::new(script);
    cmd.arg("--isolated");
    if secure {
        cmd.arg("--secure");
    }
    cmd.arg("--log-dir").arg(logs).args(["--run", "sh", "-c", inside, "sh"]).arg(logs);
    cmd.args([settle.to_string(), seconds.to_string()]);
    let exe = std::env::current_exe()?;
    if let Some(dir) = exe.parent().filter(|d| d.join("sim_arm").exists()) {
        cmd.env("SOFTCONTACT_BIN", dir);
    }
    let out = cmd.output().with_context(|| format!("running {}", script.display()))?;
    anyhow::ensure!(
        out.status.success(),
        "the {} graph run failed:\n{}",
        if secure { "secure" } else { "plain" },
        String::from_utf8_lossy(&out.stderr)
    );
    let read = |name: &str| std::fs::read_to_string(logs.join(name)).with_context(|| format!("no {name}"));
    let ticks = |name: &str| -> anyhow::Result<[f64; 3]> {
        let text = read(name)?;
        let mut t = [0.0; 3];
        for line in text.lines() {
            let mut w = line.split_whitespace();
            let (Some(n), Some(u), Some(s)) = (w.next(), w.next(), w.next()) else { continue };
            if let Some(i) = PROCESSES.iter().position(|p| *p == n) {
                t[i] += u.parse::<f64>()? + s.parse::<f64>()?;
            }
        }
        Ok(t)
    };
    let (c0, c1) = (ticks("cpu0")?, ticks("cpu1")?);
    let wall = read("t1")?.trim().parse::<f64>()? - read("t0")?.trim().parse::<f64>()?;
    // `/proc/PID/stat` counts in clock ticks: 100 a second on Linux (sysconf(_SC_CLK_TCK)).
    let cpu = std::array::from_fn(|i| 100.0 * ((c1[i] - c0[i]) / 100.0) / wall);
    let control = read("lwr_control.log")?;
    let sim = read("sim_arm.log")?;
    let latency = control.lines().find(|l| l.contains("reply latency")).context("lwr_control reported no latency")?;
    Ok(Run {
        p50_us: number_after(latency, "p50 ")?,
        p99_us: number_after(latency, "p99 ")?,
        within_200us: number_after(latency, "within 200 us: ")?,
        late_answers: number_after(&sim, "late_answers: ")?,
        cycles: number_after(&sim, "cycles: ")?,
        cpu,
    })
}

/// The number that follows `key` in `text`.
fn number_after(text: &str, key: &str) -> anyhow::Result<f64> {
    let rest = text.split(key).nth(1).with_context(|| format!("no `{key}` in {text}"))?;
    let n: String = rest.chars().take_while(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | 'e')).collect();
    n.parse().with_context(|| format!("`{key}` is followed by no number"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_read_after_their_key_from_the_exit_reports() {
        let line = "lwr_driver: reply latency n 8973 p50 65.000 p99 1818.000 p99.9 9276.000 max 133211.488 us; \
                    within 200 us: 81.6226 %";
        assert_eq!(number_after(line, "p50 ").unwrap(), 65.0);
        assert_eq!(number_after(line, "p99 ").unwrap(), 1818.0);
        assert_eq!(number_after(line, "within 200 us: ").unwrap(), 81.6226);
        let sim = "sim_arm: exit: SimArmStats { cycles: 8991, measurements_dropped: 0, late_answers: 423, }";
        assert_eq!(number_after(sim, "late_answers: ").unwrap(), 423.0);
        assert_eq!(number_after(sim, "cycles: ").unwrap(), 8991.0);
        assert!(number_after(sim, "overruns: ").is_err());
    }
}
