//! `softcontact`: the product's command line (docs/contracts.md).

mod any_topic;
mod arm_effects;
mod bench;
mod bench_graph;
mod climb_cmd;
mod closed_loop;
mod demo;
mod discrepancy_cmd;
mod discrepancy_figures;
mod force_cmd;
mod identify_cmd;
mod loading_paths_arm;
mod loading_paths_cmd;
mod loading_paths_figures;
mod loading_paths_record;
mod model_cmd;
mod ranges;
mod real_curves;
mod record_cmd;
mod security_cmd;
mod table;
mod tangential_paths;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "softcontact",
    version,
    about = "Compliant normal-force control of a torque-controlled arm on soft surfaces"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The main job without hardware: the simulated LWR pushes a simulated sponge and dice, runs seed
    /// 001's identification and control experiments, prints its tables and writes recording and figures.
    Demo(demo::DemoArgs),
    /// Fit every contact model to a recording (5-fold cross-validated fitness) and choose one.
    Identify(identify_cmd::IdentifyArgs),
    /// Find where simulation and measurement disagree, name the missing effect, add it, show the gap.
    Discrepancy(discrepancy_cmd::DiscrepancyArgs),
    /// Record ROS 2 topics to MCAP (like `ros2 bag record`).
    Record(record_cmd::RecordArgs),
    /// Publish a recording with its recorded timing (like `ros2 bag play`).
    Replay(record_cmd::ReplayArgs),
    /// The robot description as the code sees it: joints, limits, masses, frames, and at a state the
    /// frame poses, the tool Jacobian, M, g and the RNEA torque.
    Model(model_cmd::ModelArgs),
    /// Send a force command to the running deformation controller (over DDS) and report the force
    /// reached at the end of the move.
    Force(force_cmd::ForceArgs),
    /// The snake paper's 205 loading-path experiments on the simulated half-ball: Tables I–III beside the
    /// paper's, and the convergence-point spread the Mindlin–Deresiewicz law predicts.
    LoadingPaths(loading_paths_cmd::LoadingPathsArgs),
    /// The snake paper's climbing snake: a planar chain squeezed between two walls on rubber feet climbs by a
    /// gait of PD set points, each equilibrium checked stable and inside its friction cones.
    Climb(climb_cmd::ClimbArgs),
    /// The parameters of a node as its shipped file `config/<node>.yaml` (every parameter at its default,
    /// its description and range as a comment), or with --markdown the reference of every node
    /// (docs/parameters.md); both generated from the nodes' declarations.
    Params {
        /// lwr_driver, ft_sensor, contact_estimator, deformation_controller or sim_arm.
        #[arg(required_unless_present = "markdown")]
        node: Option<String>,
        /// The reference of every node, as docs/parameters.md.
        #[arg(long, conflicts_with = "node")]
        markdown: bool,
    },
    /// ROS 2 security (SROS2): keystores, and the enclave of each process with its least-privilege
    /// permissions.
    Security {
        #[command(subcommand)]
        what: security_cmd::SecurityCommand,
    },
    /// Benchmarks of the product's hot paths.
    Bench {
        #[command(subcommand)]
        what: bench::BenchCommand,
    },
}

impl Command {
    /// A command that reads files and prints a report, with no socket, node or child process.
    fn reports_only(&self) -> bool {
        matches!(
            self,
            Command::Identify(_)
                | Command::Discrepancy(_)
                | Command::Model(_)
                | Command::LoadingPaths(_)
                | Command::Climb(_)
                | Command::Params { .. }
        )
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Demo(args) => demo::run(&args),
        Command::Identify(args) => identify_cmd::run(&args),
        Command::Discrepancy(args) => discrepancy_cmd::run(&args),
        Command::Record(args) => record_cmd::record(&args),
        Command::Replay(args) => record_cmd::replay(&args),
        Command::Model(args) => model_cmd::run(args),
        Command::Force(args) => force_cmd::run(&args),
        Command::LoadingPaths(args) => loading_paths_cmd::run(&args),
        Command::Climb(args) => climb_cmd::run(&args),
        Command::Params { node, markdown } => {
            use softcontact_nodes::runtime::params::reference;
            let nodes = softcontact_simcell::parameter_reference();
            if markdown {
                print!("{}", reference::markdown_all(&nodes));
                return Ok(());
            }
            let node = node.expect("clap requires a node without --markdown");
            let Some(found) = nodes.iter().find(|n| n.node == node) else {
                let names: Vec<&str> = nodes.iter().map(|n| n.node).collect();
                anyhow::bail!("no node {node:?}: one of {}", names.join(", "));
            };
            print!("{}", found.yaml());
            Ok(())
        }
        Command::Security { what } => security_cmd::run(what),
        Command::Bench { what } => bench::run(what),
    }
}

fn main() -> ExitCode {
    softcontact_nodes::runtime::ros::init_logging("softcontact");
    let cli = Cli::parse();
    if cli.command.reports_only() {
        // A report piped into `head` ends quietly when the reader closes the pipe, as other Unix tools do,
        // instead of panicking on the failed write. Only offline commands: a node or a graph keeps
        // SIGPIPE ignored, so that a peer closing a socket is an error it handles, not its end.
        // SAFETY: setting a signal's disposition to its default before any thread is started.
        unsafe { libc::signal(libc::SIGPIPE, libc::SIG_DFL) };
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// Every command's and subcommand's help, as `--help` prints it.
    fn helps(cmd: &mut clap::Command, out: &mut Vec<(String, String)>) {
        out.push((cmd.get_name().to_string(), cmd.render_long_help().to_string()));
        for sub in cmd.get_subcommands_mut() {
            helps(sub, out);
        }
    }

    #[test]
    fn no_help_text_shows_the_escapes_rustdoc_needs() {
        let mut all = vec![];
        helps(&mut super::Cli::command(), &mut all);
        assert!(all.len() > 10, "{} commands", all.len());
        let escaped: Vec<&String> = all.iter().filter(|(_, h)| h.contains("\\[")).map(|(n, _)| n).collect();
        assert!(escaped.is_empty(), "`\\[` in the help of {escaped:?}: write units as (N) in an argument's doc");
    }
}
