//! The driver's and the sensor node's UDP ends. One socket, one owner, no threads here: the node's
//! main loop (or a test) calls `cycle`/`receive`.

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use nalgebra::UnitQuaternion;
use softcontact_wire::rdt::{RdtCommand, Request};

use crate::ft_sensor::{FtOutput, FtSensorNode};
use crate::lwr_driver::{DriverOutput, LwrDriver};
use crate::stats::Histogram;

/// A receive that ended without a datagram: the timeout passed, or a signal (shutdown) interrupted it.
pub(crate) fn no_datagram(e: &std::io::Error) -> bool {
    matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted)
}

/// The remote end of FRI: listens where the KRC sends, answers the sender of each measurement.
pub struct FriClient {
    socket: UdpSocket,
    pub driver: LwrDriver,
    /// Time from a measurement's arrival to its answer leaving the driver for the kernel [s].
    pub reply_latency: Histogram,
    /// Time the kernel takes to accept the answer (on loopback it also delivers it) [s].
    pub send_duration: Histogram,
}

impl FriClient {
    pub fn bind(addr: SocketAddr, driver: LwrDriver) -> std::io::Result<Self> {
        Ok(Self {
            socket: UdpSocket::bind(addr)?,
            driver,
            reply_latency: Histogram::new(1e-6, 20_000),
            send_duration: Histogram::new(1e-6, 20_000),
        })
    }

    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// Waits up to `timeout` for a measurement, answers it at once with the newest command, and returns
    /// what to publish; `None` on timeout. Malformed datagrams are counted by the driver and skipped.
    pub fn cycle(&mut self, timeout: Duration) -> std::io::Result<Option<DriverOutput>> {
        let mut buf = [0u8; 2048];
        self.socket.set_read_timeout(Some(timeout))?;
        loop {
            let (n, from) = match self.socket.recv_from(&mut buf) {
                Ok(r) => r,
                Err(e) if no_datagram(&e) => return Ok(None),
                Err(e) => return Err(e),
            };
            let arrived = Instant::now();
            if let Ok((reply, output)) = self.driver.handle(&buf[..n]) {
                let datagram = reply.encode();
                let sending = Instant::now();
                self.socket.send_to(&datagram, from)?;
                self.reply_latency.record((sending - arrived).as_secs_f64());
                self.send_duration.record(sending.elapsed().as_secs_f64());
                return Ok(Some(output));
            }
        }
    }
}

/// The client end of RDT, connected to one sensor.
pub struct RdtClient {
    socket: UdpSocket,
    pub node: FtSensorNode,
}

impl RdtClient {
    pub fn connect(sensor: SocketAddr, node: FtSensorNode) -> std::io::Result<Self> {
        let bind: SocketAddr = if sensor.is_ipv4() {
            "127.0.0.1:0".parse().expect("address")
        } else {
            "[::1]:0".parse().expect("address")
        };
        let socket = UdpSocket::bind(bind)?;
        socket.connect(sensor)?;
        Ok(Self { socket, node })
    }

    pub fn request(&self, command: RdtCommand, sample_count: u32) -> std::io::Result<()> {
        self.socket.send(&Request { command, sample_count }.encode()).map(|_| ())
    }

    /// Starts real-time streaming (sample count 0: until stopped).
    pub fn start(&self) -> std::io::Result<()> {
        self.request(RdtCommand::StartRealTime, 0)
    }

    pub fn stop(&self) -> std::io::Result<()> {
        self.request(RdtCommand::Stop, 0)
    }

    /// The next record, or `None` after `timeout`. Malformed datagrams are counted and skipped.
    pub fn receive(
        &mut self,
        timeout: Duration,
        orientation: Option<&UnitQuaternion<f64>>,
    ) -> std::io::Result<Option<FtOutput>> {
        let mut buf = [0u8; 2048];
        self.socket.set_read_timeout(Some(timeout))?;
        loop {
            let n = match self.socket.recv(&mut buf) {
                Ok(n) => n,
                Err(e) if no_datagram(&e) => return Ok(None),
                Err(e) => return Err(e),
            };
            if let Ok(out) = self.node.handle(&buf[..n], orientation) {
                return Ok(Some(out));
            }
        }
    }
}
