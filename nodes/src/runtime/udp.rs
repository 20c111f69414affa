//! The driver's and the sensor node's UDP ends. One socket, one owner, no threads here: the node's
//! main loop (or a test) calls `cycle`/`receive`.

use std::io::IoSliceMut;
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use nix::sys::socket::{ControlMessageOwned, MsgFlags, SockaddrStorage, recvmsg, setsockopt, sockopt};

use nalgebra::UnitQuaternion;
use softcontact_wire::rdt::{RdtCommand, Request};

use crate::ft_sensor::{FtOutput, FtSensorNode};
use crate::lwr_driver::{DriverOutput, LwrDriver};
use crate::runtime::stats::Histogram;

/// A receive that ended without a datagram: the timeout passed, or a signal (shutdown) interrupted it.
pub fn no_datagram(e: &std::io::Error) -> bool {
    matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut | std::io::ErrorKind::Interrupted)
}

/// The remote end of FRI: listens where the KRC sends, answers the pinned KRC's measurements (the
/// driver decides who that is and when a new session begins). No datagram and no socket error ends
/// it: errors are counted in the driver's counters.
pub struct FriClient {
    socket: UdpSocket,
    pub driver: LwrDriver,
    /// Time from a measurement's arrival (the kernel's receive timestamp, SO_TIMESTAMPNS: scheduling
    /// delays before `recv` returns count) to its answer leaving the driver for the kernel \[s\].
    pub reply_latency: Histogram,
    /// Time the kernel takes to accept the answer (on loopback it also delivers it) \[s\].
    pub send_duration: Histogram,
    last_arrival: Option<Instant>,
}

impl FriClient {
    pub fn bind(addr: SocketAddr, driver: LwrDriver) -> std::io::Result<Self> {
        let socket = UdpSocket::bind(addr)?;
        setsockopt(&socket, sockopt::ReceiveTimestampns, &true).map_err(std::io::Error::from)?;
        Ok(Self {
            socket,
            driver,
            reply_latency: Histogram::new(1e-6, 20_000),
            send_duration: Histogram::new(1e-6, 20_000),
            last_arrival: None,
        })
    }

    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// Waits up to `timeout` for a measurement, answers it at once with the newest command, and returns
    /// what to publish; `None` on timeout or a socket error. Malformed, implausible and strangers'
    /// datagrams are counted by the driver and skipped.
    pub fn cycle(&mut self, timeout: Duration) -> std::io::Result<Option<DriverOutput>> {
        self.cycle_with(timeout, |_, _| {})
    }

    /// [`cycle`](Self::cycle) with `respond` run between reading the measurement and answering it: an
    /// in-process controller computes the torque for this very measurement and hands it to the driver
    /// ([`LwrDriver::set_command`], or [`LwrDriver::clear_command`] to hold).
    pub fn cycle_with(
        &mut self,
        timeout: Duration,
        mut respond: impl FnMut(&mut LwrDriver, &DriverOutput),
    ) -> std::io::Result<Option<DriverOutput>> {
        let mut buf = [0u8; 2048];
        self.socket.set_read_timeout(Some(timeout))?;
        let deadline = Instant::now() + timeout;
        loop {
            let (n, from, received) = match receive(&self.socket, &mut buf) {
                Ok(r) => r,
                Err(e) if no_datagram(&e) => return Ok(None),
                Err(_) => {
                    // E.g. an ICMP error queued on the socket: count it, and never spin on it.
                    self.driver.counters.network_errors += 1;
                    std::thread::sleep(
                        Duration::from_millis(1).min(deadline.saturating_duration_since(Instant::now())),
                    );
                    if Instant::now() >= deadline {
                        return Ok(None);
                    }
                    continue;
                }
            };
            let arrived = Instant::now();
            // The kernel's timestamp, on the system clock; without one, when `recv` returned.
            let waited = received.and_then(|t| SystemTime::now().duration_since(t).ok()).unwrap_or_default();
            let silence = self.last_arrival.map_or(f64::INFINITY, |t| (arrived - t).as_secs_f64());
            if self.driver.accept_sender(from, silence).is_none() {
                continue;
            }
            if self.last_arrival.is_some() {
                self.driver.resumed_after(silence);
            }
            self.last_arrival = Some(arrived);
            if let Ok(measured) = self.driver.measure(&buf[..n]) {
                respond(&mut self.driver, &measured.output);
                let (reply, output) = self.driver.answer(measured);
                let datagram = reply.encode();
                let sending = Instant::now();
                if self.socket.send_to(&datagram, from).is_err() {
                    self.driver.counters.network_errors += 1;
                }
                self.reply_latency.record((waited + (sending - arrived)).as_secs_f64());
                self.send_duration.record(sending.elapsed().as_secs_f64());
                return Ok(Some(output));
            }
        }
    }
}

/// One datagram, its sender, and the kernel's receive timestamp (SO_TIMESTAMPNS) when there is one.
fn receive(socket: &UdpSocket, buf: &mut [u8]) -> std::io::Result<(usize, SocketAddr, Option<SystemTime>)> {
    let mut iov = [IoSliceMut::new(buf)];
    let mut space = nix::cmsg_space!(nix::sys::time::TimeSpec);
    let msg = recvmsg::<SockaddrStorage>(socket.as_raw_fd(), &mut iov, Some(&mut space), MsgFlags::empty())
        .map_err(std::io::Error::from)?;
    let timestamp = msg.cmsgs().ok().and_then(|mut c| {
        c.find_map(|m| match m {
            ControlMessageOwned::ScmTimestampns(t) => {
                Some(UNIX_EPOCH + Duration::new(t.tv_sec().try_into().ok()?, t.tv_nsec().try_into().ok()?))
            }
            _ => None,
        })
    });
    let from = msg.address.and_then(|a| {
        a.as_sockaddr_in()
            .map(|v4| SocketAddr::V4((*v4).into()))
            .or_else(|| a.as_sockaddr_in6().map(|v6| SocketAddr::V6((*v6).into())))
    });
    let from = from.ok_or_else(|| std::io::Error::other("a datagram without an IP sender"))?;
    Ok((msg.bytes, from, timestamp))
}

/// The client end of RDT, talking to one sensor. No datagram and no socket error ends it: an ICMP
/// port or host unreachable (the box not up yet, or rebooting), a missing route or a stranger's datagram
/// is counted in the node's counters, and while no fresh record arrives the start request goes out
/// again every `restart_after`, so the stream begins whenever the box comes up.
pub struct RdtClient {
    socket: UdpSocket,
    sensor: SocketAddr,
    connected: bool,
    pub node: FtSensorNode,
    /// A silence this long ends a stream: a restarted sequence after it is a new stream, not a replay.
    pub new_stream_after: Duration,
    /// While no fresh record arrives for this long, the start request is sent again.
    pub restart_after: Duration,
    last_datagram: Option<Instant>,
    last_fresh: Instant,
    last_start: Option<Instant>,
}

impl RdtClient {
    /// A socket on an ephemeral port of every interface, connected to the sensor when a route to it
    /// exists (the kernel then picks the interface that faces the box, and drops other senders' datagrams);
    /// until then connecting is retried with each start request.
    pub fn connect(sensor: SocketAddr, node: FtSensorNode) -> std::io::Result<Self> {
        let bind: SocketAddr = if sensor.is_ipv4() {
            (std::net::Ipv4Addr::UNSPECIFIED, 0).into()
        } else {
            (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
        };
        let socket = UdpSocket::bind(bind)?;
        let mut client = Self {
            socket,
            sensor,
            connected: false,
            node,
            new_stream_after: Duration::from_millis(100),
            restart_after: Duration::from_secs(1),
            last_datagram: None,
            last_fresh: Instant::now(),
            last_start: None,
        };
        client.try_connect();
        Ok(client)
    }

    fn try_connect(&mut self) {
        if !self.connected {
            match self.socket.connect(self.sensor) {
                Ok(()) => self.connected = true,
                Err(_) => self.node.counters.network_errors += 1,
            }
        }
    }

    /// Sends a request; a failure is counted and returned (it never needs to end the caller).
    pub fn request(&mut self, command: RdtCommand, sample_count: u32) -> std::io::Result<()> {
        self.try_connect();
        let datagram = Request { command, sample_count }.encode();
        let sent =
            if self.connected { self.socket.send(&datagram) } else { self.socket.send_to(&datagram, self.sensor) };
        sent.map(|_| ()).inspect_err(|_| self.node.counters.network_errors += 1)
    }

    /// Starts real-time streaming (sample count 0: until stopped); the box restarts its sequence.
    pub fn start(&mut self) -> std::io::Result<()> {
        self.last_start = Some(Instant::now());
        self.node.new_stream();
        self.request(RdtCommand::StartRealTime, 0)
    }

    pub fn stop(&mut self) -> std::io::Result<()> {
        self.request(RdtCommand::Stop, 0)
    }

    /// Time since the last fresh record (or since the client was made).
    pub fn silence(&self) -> Duration {
        self.last_fresh.elapsed()
    }

    /// The next fresh record, or `None` after `timeout`. Malformed, repeated, out-of-order and
    /// strangers' datagrams and socket errors are counted and skipped; while no fresh record arrives
    /// the start request is repeated every `restart_after`.
    pub fn receive(
        &mut self,
        timeout: Duration,
        orientation: Option<&UnitQuaternion<f64>>,
    ) -> std::io::Result<Option<FtOutput>> {
        let mut buf = [0u8; 2048];
        let deadline = Instant::now() + timeout;
        loop {
            if self.last_fresh.elapsed() >= self.restart_after
                && self.last_start.is_none_or(|t| t.elapsed() >= self.restart_after)
            {
                // The box may be booting, or have given our stream to another client: ask again.
                let _ = self.start();
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.socket.set_read_timeout(Some(left))?;
            let (n, from) = match self.socket.recv_from(&mut buf) {
                Ok(r) => r,
                Err(e) if no_datagram(&e) => return Ok(None),
                Err(_) => {
                    // E.g. ECONNREFUSED from an ICMP port unreachable: count it, and never spin on it.
                    self.node.counters.network_errors += 1;
                    std::thread::sleep(
                        Duration::from_millis(1).min(deadline.saturating_duration_since(Instant::now())),
                    );
                    continue;
                }
            };
            if from != self.sensor {
                self.node.counters.foreign += 1;
                continue;
            }
            let now = Instant::now();
            if self.last_datagram.is_some_and(|t| now - t >= self.new_stream_after) {
                self.node.new_stream();
            }
            self.last_datagram = Some(now);
            match self.node.handle(&buf[..n], orientation) {
                Ok(out) if out.fresh => {
                    self.last_fresh = now;
                    return Ok(Some(out));
                }
                _ => {}
            }
        }
    }
}

/// Waits until `socket` has a datagram or `timeout` has passed (`ppoll`: to the microsecond, where a
/// socket's receive timeout is rounded up to the kernel's tick, 4 ms on many kernels). True if readable.
pub fn wait_readable(socket: &UdpSocket, timeout: Duration) -> std::io::Result<bool> {
    use nix::poll::{PollFd, PollFlags, ppoll};
    use std::os::fd::AsFd;
    let mut fds = [PollFd::new(socket.as_fd(), PollFlags::POLLIN)];
    match ppoll(&mut fds, Some(nix::sys::time::TimeSpec::from_duration(timeout)), None) {
        Ok(n) => Ok(n > 0),
        Err(nix::errno::Errno::EINTR) => Ok(false),
        Err(e) => Err(e.into()),
    }
}
