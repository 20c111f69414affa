//! A RustDDS participant with DDS-Security's builtin plugins, configured from an enclave of an SROS2
//! keystore (`cert.pem`, `key.pem`, `identity_ca.cert.pem`, `permissions_ca.cert.pem`,
//! `governance.p7s`, `permissions.p7s`: RustDDS's `with_ros_default_names`).
//!
//! It writes `hello N` on `rt/chatter` every 50 ms and reads `rt/reply` (both `std_msgs/String` under its
//! ROS 2 DDS type name, reliable), and prints `read TEXT` for each sample read and `wrote N` at the end,
//! for tests/security_interop.rs to judge. Exits 2 when it read nothing.
//!
//! With `echo`, it is the other side instead: it reads `rt/chatter` and answers each sample on `rt/reply`
//! from two writers, as two nodes of one process do (`ack1 TEXT` and `ack2 TEXT`).
//!
//! Usage: rustdds-secure-peer ENCLAVE_DIR SECONDS [echo]   (RUST_LOG=info shows the handshake)
use std::time::{Duration, Instant};

use rustdds::{
    no_key::{DataReader, DataWriter},
    policy::{Durability, History, Reliability},
    CDRDeserializerAdapter, CDRSerializerAdapter, DomainParticipantBuilder, DomainParticipantSecurityConfigFiles,
    QosPolicyBuilder, TopicKind,
};
use serde::{Deserialize, Serialize};

/// std_msgs/String.
#[derive(Serialize, Deserialize, Debug, Clone)]
struct Text {
    data: String,
}

const TYPE_NAME: &str = "std_msgs::msg::dds_::String_";

fn main() {
    env_logger::init();
    let mut args = std::env::args().skip(1);
    let (Some(enclave), Some(seconds)) = (args.next(), args.next().and_then(|s| s.parse::<f64>().ok())) else {
        eprintln!("usage: rustdds-secure-peer ENCLAVE_DIR SECONDS [echo]");
        std::process::exit(1);
    };
    let echo = args.next().as_deref() == Some("echo");
    let files = DomainParticipantSecurityConfigFiles::with_ros_default_names(&enclave, String::new());
    let participant = match DomainParticipantBuilder::new(0).builtin_security(files).build() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("no secure participant from {enclave}: {e:?}");
            std::process::exit(1);
        }
    };
    let qos = QosPolicyBuilder::new()
        .reliability(Reliability::Reliable { max_blocking_time: rustdds::Duration::from_millis(100) })
        .history(History::KeepLast { depth: 10 })
        .durability(Durability::Volatile)
        .build();
    let topic =
        |name: &str| participant.create_topic(name.into(), TYPE_NAME.into(), &qos, TopicKind::NoKey).expect("topic");
    let (chatter, reply) = (topic("rt/chatter"), topic("rt/reply"));
    let (publisher, subscriber) =
        (participant.create_publisher(&qos).unwrap(), participant.create_subscriber(&qos).unwrap());
    let writer = |topic: &rustdds::Topic| -> DataWriter<Text, CDRSerializerAdapter<Text>> {
        publisher.create_datawriter_no_key(topic, None).expect("writer")
    };
    let mut reader: DataReader<Text, CDRDeserializerAdapter<Text>> =
        subscriber.create_datareader_no_key(if echo { &chatter } else { &reply }, None).expect("reader");
    let writers = if echo { vec![writer(&reply), writer(&reply)] } else { vec![writer(&chatter)] };
    let start = Instant::now();
    let (mut wrote, mut read) = (0, 0);
    while start.elapsed().as_secs_f64() < seconds {
        if !echo && writers[0].write(Text { data: format!("hello {wrote}") }, None).is_ok() {
            wrote += 1;
        }
        while let Ok(Some(sample)) = reader.take_next_sample() {
            let text = &sample.value().data;
            println!("read {text}");
            read += 1;
            for (i, w) in writers.iter().enumerate().filter(|_| echo) {
                if w.write(Text { data: format!("ack{} {text}", i + 1) }, None).is_ok() {
                    wrote += 1;
                }
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    println!("wrote {wrote}");
    std::process::exit(if read > 0 { 0 } else { 2 });
}
