//! `softcontact record` and `softcontact replay`: like `ros2 bag record` and `ros2 bag play`, in MCAP.

use softcontact_msgs::topics;
use std::io::Write;
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use softcontact_bag::{AnyMessage, BagWriter, Qos, Recording, Topic};
use softcontact_nodes::runtime::ros;

use crate::any_topic::{AnyPublisher, AnySubscription, graph_topics};

#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// Where to write: NAME.mcap for one file, anything else for a rosbag2 folder
    /// (default: softcontact_YYYY_MM_DD-HH_MM_SS, a folder).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Topics to record, as NAME (a topic of the graph) or NAME:pkg/msg/Type (default: every topic of
    /// the graph).
    pub topics: Vec<String>,
    /// Stop after this many seconds (default: at Ctrl-C / SIGTERM).
    #[arg(long, value_parser = crate::ranges::real(0.001, 1e7, " s"))]
    pub duration: Option<f64>,
    /// The enclave on a secure graph (`ROS_SECURITY_ENABLE=true`), e.g. /user, whose permissions read every stream.
    #[arg(long)]
    pub enclave: Option<String>,
}

#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// A recording: an .mcap file or a rosbag2 folder.
    pub file: PathBuf,
    /// Speed factor of the recorded timing, 0.01 to 100.
    #[arg(long, default_value_t = 1.0, value_parser = rate)]
    pub rate: f64,
    /// Start again at the end, until Ctrl-C.
    #[arg(long = "loop")]
    pub looping: bool,
    /// Replay only these topics (default: all whose type the project knows, but the actuator topics).
    #[arg(long, value_delimiter = ',')]
    pub topics: Vec<String>,
    /// Longest wait for subscribers before the first message (s), 0 to 3600: the replay starts once every
    /// replayed topic has one, or once some have and none gained one for a second (a secure graph's
    /// handshakes take seconds).
    #[arg(long, default_value_t = 10.0, value_parser = wait)]
    pub wait: f64,
    /// Also publish the recorded commands to the arm (see ACTUATOR_TOPICS): into a live graph they move
    /// it. Without this flag they are never published.
    #[arg(long)]
    pub actuators: bool,
    /// The enclave on a secure graph (`ROS_SECURITY_ENABLE=true`): its permissions decide what may be
    /// published (/user's do not include the actuator topics).
    #[arg(long)]
    pub enclave: Option<String>,
}

/// Recorded topics whose messages command the arm when published into a live graph: torques the driver
/// applies, force commands the controller executes, contact models the controller places its pushes with.
pub const ACTUATOR_TOPICS: [(&str, &str); 3] = [
    (topics::JOINT_TORQUE_COMMAND.name, "the driver applies them to the arm"),
    (topics::FORCE_COMMAND.name, "the controller moves the arm to them"),
    (topics::CONTACT_MODEL.name, "the controller places its pushes with it"),
];

/// Types that command the arm on whatever topic they were recorded.
const ACTUATOR_TYPES: [&str; 2] = ["softcontact_msgs/msg/ForceCommand", "softcontact_msgs/msg/ContactModel"];

/// Why a recorded topic commands the arm, if it does.
pub fn actuator(topic: &str, type_name: &str) -> Option<&'static str> {
    ACTUATOR_TOPICS.iter().find(|(t, _)| *t == topic).map(|(_, why)| *why).or_else(|| {
        ACTUATOR_TYPES
            .contains(&softcontact_bag::type_path(type_name).as_str())
            .then_some("its type commands the controller")
    })
}

fn in_range(s: &str, name: &str, low: f64, high: f64, unit: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("{name} takes a number, not `{s}`"))?;
    if v.is_finite() && (low..=high).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{name} must be between {low} and {high}{unit} (got {s})"))
    }
}

fn rate(s: &str) -> Result<f64, String> {
    in_range(s, "--rate", 0.01, 100.0, "")
}

fn wait(s: &str) -> Result<f64, String> {
    in_range(s, "--wait", 0.0, 3600.0, " s")
}

fn now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

/// `softcontact_YYYY_MM_DD-HH_MM_SS` (UTC), as `ros2 bag record` names its folders.
fn default_name() -> PathBuf {
    let secs = now_ns() / 1_000_000_000;
    let (days, rest) = ((secs / 86_400) as i64, secs % 86_400);
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    PathBuf::from(format!(
        "softcontact_{year:04}_{month:02}_{day:02}-{:02}_{:02}_{:02}",
        rest / 3600,
        rest / 60 % 60,
        rest % 60
    ))
}

/// User + system CPU time of this process so far (Linux /proc, clock ticks of 10 ms).
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// The topics asked for, with types and QoS.
fn resolve(topics: &[String]) -> anyhow::Result<Vec<(String, String, Qos)>> {
    if topics.is_empty() {
        return Ok(graph_topics().into_iter().map(|(n, t, q)| (n.to_string(), t, q)).collect());
    }
    let graph = graph_topics();
    topics
        .iter()
        .map(|spec| {
            let (name, ty) = spec.split_once(':').map_or((spec.as_str(), None), |(n, t)| (n, Some(t)));
            anyhow::ensure!(name.starts_with('/'), "topic `{name}`: names start with /");
            let known = graph.iter().find(|(n, _, _)| *n == name);
            match (ty, known) {
                (Some(ty), _) => {
                    anyhow::ensure!(AnyMessage::is_known(ty), "{name}: type {ty} is not one the project knows");
                    Ok((name.to_string(), softcontact_bag::type_path(ty), known.map_or(Qos::SENSOR, |k| k.2)))
                }
                (None, Some((_, ty, qos))) => Ok((name.to_string(), ty.to_string(), *qos)),
                (None, None) => anyhow::bail!(
                    "{name} is not a topic of the graph; give its type as {name}:pkg/msg/Type (graph topics: {})",
                    graph.iter().map(|t| t.0).collect::<Vec<_>>().join(" ")
                ),
            }
        })
        .collect()
}

pub fn record(args: &RecordArgs) -> anyhow::Result<()> {
    let topics = resolve(&args.topics)?;
    let output = args.output.clone().unwrap_or_else(default_name);
    let stop = ros::shutdown_flag()?;
    let mut node = ros::tool_node("softcontact_record", "/", args.enclave.as_deref())?;
    let mut writer = BagWriter::create(&output)?;
    let mut subscriptions = Vec::new();
    let mut poll = mio::Poll::new()?;
    let mut events = mio::Events::with_capacity(64);
    for (i, (name, ty, qos)) in topics.iter().enumerate() {
        let mut sub = AnySubscription::new(&mut node, name, ty, *qos)?;
        sub.register(poll.registry(), mio::Token(i))?;
        let channel = writer.add_topic_with_definition(
            name,
            ty,
            softcontact_msgs::definition(ty).expect("known types have definitions"),
            *qos,
        )?;
        subscriptions.push((sub, channel, name.as_str(), *qos));
        println!("recording {name} ({ty})");
    }
    println!("to {} (Ctrl-C stops)", writer.file().display());
    let start = Instant::now();
    let mut next_flush = start + Duration::from_secs(1);
    let mut total = 0u64;
    while !ros::stopping(&stop) && args.duration.is_none_or(|d| start.elapsed().as_secs_f64() < d) {
        let mut got = 0;
        for (sub, channel, _, _) in &subscriptions {
            while let Some(msg) = sub.take() {
                msg.write_to_channel(&mut writer, *channel, now_ns())?;
                got += 1;
            }
        }
        total += got;
        if Instant::now() >= next_flush {
            // A chunk a second: a recorder killed now loses at most the last second.
            writer.flush()?;
            next_flush += Duration::from_secs(1);
            print!("\rrecorded {total} messages in {:.0} s", start.elapsed().as_secs_f64());
            std::io::stdout().flush()?;
        }
        if got == 0 {
            // Until a subscription has news (or the next flush is due).
            ros::wait(&mut poll, &mut events, Duration::from_millis(100))?;
        }
    }
    let elapsed = start.elapsed().as_secs_f64();
    let counts: Vec<String> = writer.counts().filter(|(_, n)| *n > 0).map(|(t, n)| format!("{t} {n}")).collect();
    let stats = writer.finish()?;
    println!(
        "\nrecorded {} messages, {:.1} MB in {elapsed:.1} s to {}: {}",
        stats.messages,
        stats.bytes as f64 / 1e6,
        output.display(),
        counts.join(", ")
    );
    if let Some(cpu) = cpu_seconds() {
        println!("CPU {cpu:.2} s: {:.1} % of one core (DDS reception included)", 100.0 * cpu / elapsed.max(1e-9));
    }
    Ok(())
}

/// Waits until every publisher has a subscription, or some have and no new one matched for a second, or
/// `longest` has passed; says which topics have none.
fn wait_for_subscribers(
    node: &ros2_client::Node,
    publishers: &[(String, AnyPublisher)],
    longest: Duration,
    stop: &std::sync::atomic::AtomicBool,
) {
    const QUIET: Duration = Duration::from_secs(1);
    let start = Instant::now();
    let mut matched = 0;
    let mut last_match = start;
    loop {
        let counts: Vec<usize> = publishers.iter().map(|(_, p)| p.subscription_count(node)).collect();
        let total: usize = counts.iter().sum();
        if total > matched {
            matched = total;
            last_match = Instant::now();
        }
        let all = counts.iter().all(|&c| c > 0);
        let settled = matched > 0 && last_match.elapsed() >= QUIET;
        if all || settled || start.elapsed() >= longest || ros::stopping(stop) {
            let unmatched: Vec<&str> =
                publishers.iter().zip(&counts).filter(|(_, c)| **c == 0).map(|((n, _), _)| n.as_str()).collect();
            if !unmatched.is_empty() {
                eprintln!(
                    "after {:.1} s, no subscriber yet for {} (replayed all the same)",
                    start.elapsed().as_secs_f64(),
                    unmatched.join(", ")
                );
            }
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

pub fn replay(args: &ReplayArgs) -> anyhow::Result<()> {
    // The parsers hold these; a caller building ReplayArgs itself is checked too.
    rate(&args.rate.to_string()).map_err(anyhow::Error::msg)?;
    wait(&args.wait.to_string()).map_err(anyhow::Error::msg)?;
    let recording = Recording::open(&args.file)?;
    let mut said = recording.warnings();
    for w in &said {
        eprintln!("warning: {w}");
    }
    let plan = replay_plan(&recording, args)?;
    let stop = ros::shutdown_flag()?;
    let mut node = ros::tool_node("softcontact_replay", "/", args.enclave.as_deref())?;
    let mut publishers = Vec::new();
    for topic in plan {
        let qos = topic.qos.or_else(|| graph_topics().into_iter().find(|t| t.0 == topic.name).map(|t| t.2));
        let publisher = AnyPublisher::new(&mut node, &topic.name, &topic.type_name, qos.unwrap_or(Qos::SENSOR))?;
        let what = if actuator(&topic.name, &topic.type_name).is_some() { ", commands to the arm" } else { "" };
        println!("replaying {} ({}, {} messages{what})", topic.name, topic.type_name, topic.message_count);
        publishers.push((topic.name.clone(), publisher));
    }
    let span = recording.time_range().map_or(0.0, |(a, b)| b.saturating_sub(a) as f64 * 1e-9);
    ros::spin(&mut node, "softcontact_replay")?;
    wait_for_subscribers(&node, &publishers, Duration::from_secs_f64(args.wait), &stop);
    let mut sent = 0u64;
    'replay: loop {
        let start = Instant::now();
        // The timing's origin is the first message read, whatever a summary says.
        let mut origin = None;
        for m in recording.messages() {
            let m = m?;
            let Some((_, publisher)) = publishers.iter().find(|(n, _)| n == m.topic()) else { continue };
            let since = m.log_time.saturating_sub(*origin.get_or_insert(m.log_time)) as f64 * 1e-9;
            let due = start + Duration::from_secs_f64((since / args.rate).min(1e9));
            loop {
                if ros::stopping(&stop) {
                    break 'replay;
                }
                let now = Instant::now();
                if now >= due {
                    break;
                }
                std::thread::sleep((due - now).min(Duration::from_millis(50)));
            }
            let Some(msg) = AnyMessage::decode(&m)? else { continue };
            publisher.publish(msg)?;
            sent += 1;
            if sent.is_multiple_of(1000) {
                print!("\rreplayed {sent} messages, {since:.1} of {span:.1} s");
                std::io::stdout().flush()?;
            }
        }
        // Damage found while reading (a chunk skipped: its messages were not published).
        let now = recording.warnings();
        for w in now.iter().skip(said.len()) {
            eprintln!("\nwarning: {w}");
        }
        said = now;
        if !args.looping {
            break;
        }
    }
    // The last messages of a reliable topic may still await their acknowledgment: leaving now would
    // take them along.
    let unacknowledged: Vec<&str> = publishers
        .iter()
        .filter(|(_, p)| !p.wait_for_acknowledgments(Duration::from_secs(2)))
        .map(|(n, _)| n.as_str())
        .collect();
    if !unacknowledged.is_empty() {
        eprintln!("not acknowledged within 2 s by every subscriber: {}", unacknowledged.join(", "));
    }
    println!("\nreplayed {sent} messages");
    Ok(())
}

/// The recording's topics `args` asks for and the project can publish; a topic that commands the arm only
/// with `--actuators` (an error when named, skipped and said otherwise).
fn replay_plan<'a>(recording: &'a Recording, args: &ReplayArgs) -> anyhow::Result<Vec<&'a Topic>> {
    let mut plan = Vec::new();
    for topic in recording.topics() {
        if !args.topics.is_empty() && !args.topics.contains(&topic.name) {
            continue;
        }
        if !AnyMessage::is_known(&topic.type_name) {
            eprintln!("skipping {} ({}): not a type the project knows", topic.name, topic.type_name);
            continue;
        }
        if let Some(why) = actuator(&topic.name, &topic.type_name)
            && !args.actuators
        {
            anyhow::ensure!(
                args.topics.is_empty(),
                "{} commands the arm ({why}): replaying it into a live graph moves the arm; add --actuators if \
                 that is what you want",
                topic.name
            );
            eprintln!(
                "skipping {} ({}, {} messages): it commands the arm ({why}); --actuators replays it",
                topic.name, topic.type_name, topic.message_count
            );
            continue;
        }
        plan.push(topic);
    }
    for wanted in &args.topics {
        anyhow::ensure!(plan.iter().any(|t| &t.name == wanted), "the recording has no {wanted} to replay");
    }
    anyhow::ensure!(!plan.is_empty(), "nothing to replay");
    Ok(plan)
}
