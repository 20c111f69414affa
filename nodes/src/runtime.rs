//! What runs the nodes, apart from what they compute: ROS 2 wiring (nodes, QoS, parameters, names,
//! remapping), the UDP ends of FRI and RDT, stream liveness, the pinning of the command's writer, the
//! hand-over of the newest value between threads, real-time scheduling, the latency statistics, and
//! each process's enclave on a secure graph.

pub mod enclaves;
pub mod handover;
pub mod liveness;
pub mod names;
pub mod params;
pub mod realtime;
pub mod ros;
pub mod security;
pub mod stats;
pub mod udp;
pub mod writer_pin;
