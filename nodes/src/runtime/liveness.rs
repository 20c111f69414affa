//! Is the middleware alive? A node cannot ask DDS that, but it knows which streams are due: a stream
//! published at a known rate that has gone silent for much longer than its period, after it was
//! flowing, means its publisher or the middleware (ours or theirs) is dead. [`StreamWatch`] is that
//! policy for one stream, on plain seconds of a monotonic clock; the node binaries feed it the arrival
//! time of every message and decide what to do when it says [`Liveness::Dead`] (the driver holds the
//! arm and reports, the other nodes exit non-zero so that the launch script stops the graph).

use std::fmt;
use std::ops::RangeInclusive;

/// The bounds of every node's `dead_after` parameter \[s\].
pub const DEAD_AFTER_RANGE: RangeInclusive<f64> = 0.1..=60.0;

/// Declares a node's `dead_after` parameter: a liveness time within [`DEAD_AFTER_RANGE`], above `lowest`.
pub fn declare_dead_after(
    d: &mut crate::runtime::params::Declarations,
    dead_after: f64,
    lowest: f64,
    description: &str,
) {
    let (lo, hi) = (*DEAD_AFTER_RANGE.start(), *DEAD_AFTER_RANGE.end());
    if lowest < lo {
        d.within("dead_after", dead_after, (lo, hi), description);
    } else {
        d.above("dead_after", dead_after, (lowest, hi), description);
    }
}

/// What a [`StreamWatch`] says of its stream at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Liveness {
    /// Never seen (or not due since it was last seen): no verdict; a node starting before its
    /// publishers is not a fault.
    NotYet,
    /// Seen within `dead_after`; the silence so far \[s\].
    Alive(f64),
    /// Seen once, then silent for longer than `dead_after` while due; the silence \[s\].
    Dead(f64),
}

/// One stream that is due at `rate` once it has been seen.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamWatch {
    topic: String,
    rate: f64,
    dead_after: f64,
    /// The newest message, or the newest time the stream was not due [s].
    last: Option<f64>,
}

impl StreamWatch {
    /// A watch of `topic`, due at `rate` \[Hz\], dead after `dead_after` \[s\] of silence.
    pub fn new(topic: impl Into<String>, rate: f64, dead_after: f64) -> Self {
        Self { topic: topic.into(), rate, dead_after, last: None }
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// A message arrived at `t` \[s\]. Times never go back (an earlier `t` is ignored).
    pub fn seen(&mut self, t: f64) {
        if t.is_finite() {
            self.last = Some(self.last.map_or(t, |l| l.max(t)));
        }
    }

    /// The stream is not due at `t` (its source paused on purpose): silence counts again from `t`.
    /// A stream never seen stays "not yet".
    pub fn not_due(&mut self, t: f64) {
        if self.last.is_some() {
            self.seen(t);
        }
    }

    /// Forgets the stream: "not yet" until it is seen again.
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// The verdict at `t` \[s\].
    pub fn check(&self, t: f64) -> Liveness {
        match self.last {
            None => Liveness::NotYet,
            Some(last) => {
                let silence = (t - last).max(0.0);
                if silence > self.dead_after { Liveness::Dead(silence) } else { Liveness::Alive(silence) }
            }
        }
    }

    /// `Some` when the stream is dead at `t`: what to report.
    pub fn dead(&self, t: f64) -> Option<DeadStream> {
        match self.check(t) {
            Liveness::Dead(silence) => Some(DeadStream { topic: self.topic.clone(), rate: self.rate, silence }),
            _ => None,
        }
    }
}

/// The first dead stream of `watches` at `t`, if any.
pub fn first_dead(watches: &[&StreamWatch], t: f64) -> Option<DeadStream> {
    watches.iter().find_map(|w| w.dead(t))
}

/// A stream found dead, as the error a node reports.
#[derive(Debug, Clone, PartialEq)]
pub struct DeadStream {
    pub topic: String,
    /// Its rate \[Hz\].
    pub rate: f64,
    /// How long it has been silent \[s\].
    pub silence: f64,
}

impl fmt::Display for DeadStream {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: no message for {:.2} s (due at {} Hz): its publisher stopped or the middleware (DDS) is dead",
            self.topic, self.silence, self.rate
        )
    }
}

impl std::error::Error for DeadStream {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stream_never_seen_is_not_yet_dead() {
        let w = StreamWatch::new("/lwr/joint_states", 1000.0, 2.0);
        assert_eq!(w.check(0.0), Liveness::NotYet);
        assert_eq!(w.check(1e6), Liveness::NotYet);
        assert!(w.dead(1e6).is_none());
    }

    #[test]
    fn a_stream_that_stops_is_dead_after_the_bound_and_alive_again_when_it_resumes() {
        let mut w = StreamWatch::new("/lwr/ee_pose", 1000.0, 2.0);
        for i in 0..1000 {
            w.seen(10.0 + i as f64 * 1e-3);
        }
        let last = 10.999;
        assert!(matches!(w.check(last + 0.5), Liveness::Alive(s) if (s - 0.5).abs() < 1e-9));
        assert!(matches!(w.check(last + 2.0), Liveness::Alive(_)), "at the bound: still alive");
        let d = w.dead(last + 2.01).expect("dead just past the bound");
        assert_eq!(d.topic, "/lwr/ee_pose");
        assert!((d.silence - 2.01).abs() < 1e-9);
        let text = d.to_string();
        assert!(text.contains("/lwr/ee_pose") && text.contains("2.01 s") && text.contains("dead"), "{text}");
        w.seen(last + 3.0);
        assert!(matches!(w.check(last + 3.001), Liveness::Alive(_)));
    }

    #[test]
    fn time_going_back_or_not_finite_does_not_revive_or_kill() {
        let mut w = StreamWatch::new("/ft_sensor/wrench", 1000.0, 1.0);
        w.seen(5.0);
        w.seen(1.0);
        w.seen(f64::NAN);
        w.seen(f64::INFINITY);
        assert!(matches!(w.check(5.5), Liveness::Alive(_)));
        assert!(w.dead(6.01).is_some());
        assert!(matches!(w.check(4.0), Liveness::Alive(s) if s == 0.0));
    }

    #[test]
    fn silence_counts_only_while_the_stream_is_due() {
        let mut w = StreamWatch::new("/lwr/joint_torque_command", 1000.0, 2.0);
        w.not_due(0.0);
        assert_eq!(w.check(100.0), Liveness::NotYet, "not_due does not arm a watch never seen");
        w.seen(1.0);
        // Not due from 1 s to 10 s (the KRC stopped commanding): no verdict counts that time.
        for i in 0..=90 {
            w.not_due(1.0 + i as f64 * 0.1);
        }
        assert!(w.dead(11.5).is_none());
        assert!(w.dead(12.01).is_some(), "due again from 10 s: dead 2 s later");
        w.reset();
        assert_eq!(w.check(100.0), Liveness::NotYet);
    }

    #[test]
    fn the_first_dead_stream_is_named() {
        let mut a = StreamWatch::new("/ft_sensor/wrench", 1000.0, 1.0);
        let mut b = StreamWatch::new("/lwr/ee_pose", 1000.0, 1.0);
        let c = StreamWatch::new("/never", 1000.0, 1.0);
        a.seen(0.0);
        b.seen(0.0);
        assert!(first_dead(&[&a, &b, &c], 0.5).is_none());
        a.seen(2.0);
        assert_eq!(first_dead(&[&a, &b, &c], 2.0).unwrap().topic, "/lwr/ee_pose");
    }

    #[test]
    fn dead_after_is_bounded() {
        let check = |dead_after: f64, lowest: f64| {
            let mut d = crate::runtime::params::Declarations::default();
            declare_dead_after(&mut d, dead_after, lowest, "silence");
            d.error().is_none()
        };
        for ok in [0.1, 2.0, 60.0] {
            assert!(check(ok, 0.0), "{ok}");
        }
        for bad in [0.0, 0.05, -1.0, 61.0, f64::NAN, f64::INFINITY] {
            assert!(!check(bad, 0.0), "{bad}");
        }
        assert!(!check(1.0, 1.0) && check(1.01, 1.0), "above the lowest");
    }
}
