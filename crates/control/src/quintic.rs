//! Fifth-order polynomial references (the force-control paper: 2 s between set-points): position, velocity and
//! acceleration exact at both ends, so consecutive moves join without jumps in any of them.

/// One move from (p₀, v₀, a₀) to (p₁, v₁, a₁) in `duration` seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quintic {
    coefficients: [f64; 6],
    duration: f64,
}

/// Position, velocity and acceleration at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Reference {
    pub position: f64,
    pub velocity: f64,
    pub acceleration: f64,
}

impl Quintic {
    /// The unique quintic with the given boundary states. `None` for a non-positive or non-finite
    /// duration or boundary, or when its powers leave f64's range (beyond ~1e61 s, where the coefficients become NaN or
    /// silently zero).
    pub fn new(start: Reference, end: Reference, duration: f64) -> Option<Self> {
        let values = [start.position, start.velocity, start.acceleration, end.position, end.velocity, end.acceleration];
        if !(duration.is_finite() && duration > 0.0) || values.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let (p0, v0, a0) = (start.position, start.velocity, start.acceleration);
        let (p1, v1, a1) = (end.position, end.velocity, end.acceleration);
        let t = duration;
        let (t2, t3, t4, t5) = (t * t, t * t * t, t.powi(4), t.powi(5));
        // Closed form of the 6×6 boundary-value system.
        let c3 = (20.0 * (p1 - p0) - (8.0 * v1 + 12.0 * v0) * t - (3.0 * a0 - a1) * t2) / (2.0 * t3);
        let c4 = (30.0 * (p0 - p1) + (14.0 * v1 + 16.0 * v0) * t + (3.0 * a0 - 2.0 * a1) * t2) / (2.0 * t4);
        let c5 = (12.0 * (p1 - p0) - 6.0 * (v1 + v0) * t - (a0 - a1) * t2) / (2.0 * t5);
        let coefficients = [p0, v0, a0 / 2.0, c3, c4, c5];
        let representable = t5.is_normal() && coefficients.iter().all(|c| c.is_finite());
        representable.then_some(Self { coefficients, duration })
    }

    /// From rest to rest.
    pub fn rest_to_rest(from: f64, to: f64, duration: f64) -> Option<Self> {
        Self::new(
            Reference { position: from, ..Default::default() },
            Reference { position: to, ..Default::default() },
            duration,
        )
    }

    pub fn duration(&self) -> f64 {
        self.duration
    }

    /// The largest |velocity| over the move (sampled at 1 % of its duration, and both ends).
    pub fn peak_velocity(&self) -> f64 {
        (0..=100).map(|i| self.at(self.duration * i as f64 / 100.0).velocity.abs()).fold(0.0, f64::max)
    }

    /// The reference at time t after the start; before the start it is the start, after the end the
    /// end state continued at constant velocity (zero for moves that end at rest).
    pub fn at(&self, t: f64) -> Reference {
        let c = &self.coefficients;
        let tc = t.clamp(0.0, self.duration);
        let p = c[0] + tc * (c[1] + tc * (c[2] + tc * (c[3] + tc * (c[4] + tc * c[5]))));
        let v = c[1] + tc * (2.0 * c[2] + tc * (3.0 * c[3] + tc * (4.0 * c[4] + tc * 5.0 * c[5])));
        let a = 2.0 * c[2] + tc * (6.0 * c[3] + tc * (12.0 * c[4] + tc * 20.0 * c[5]));
        if t > self.duration {
            Reference { position: p + v * (t - self.duration), velocity: v, acceleration: 0.0 }
        } else {
            Reference { position: p, velocity: v, acceleration: a }
        }
    }
}

/// A sequence of set-points reached one after another by rest-to-rest quintics of equal duration.
#[derive(Debug, Clone, PartialEq)]
pub struct SetpointSequence {
    moves: Vec<Quintic>,
    segment: f64,
}

impl SetpointSequence {
    pub fn new(start: f64, setpoints: &[f64], segment: f64) -> Option<Self> {
        let mut from = start;
        let mut moves = Vec::with_capacity(setpoints.len());
        for &to in setpoints {
            moves.push(Quintic::rest_to_rest(from, to, segment)?);
            from = to;
        }
        Some(Self { moves, segment })
    }

    pub fn duration(&self) -> f64 {
        self.segment * self.moves.len() as f64
    }

    /// The reference at time t from the start of the sequence, and the index of the move in progress.
    pub fn at(&self, t: f64) -> (Reference, usize) {
        if self.moves.is_empty() {
            return (Reference::default(), 0);
        }
        let i = ((t.max(0.0) / self.segment) as usize).min(self.moves.len() - 1);
        (self.moves[i].at(t - i as f64 * self.segment), i)
    }
}

/// A sinusoid about `mean` that starts at its lowest point, mean − amplitude, at rest: the force-control paper's
/// identification pushes. The start has acceleration amplitude·ω², so a quintic that ends in
/// [`Oscillation::start`] joins it without a jump in any derivative.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Oscillation {
    pub mean: f64,
    pub amplitude: f64,
    /// \[Hz\]
    pub frequency: f64,
    pub periods: u32,
}

impl Oscillation {
    fn omega(&self) -> f64 {
        std::f64::consts::TAU * self.frequency
    }

    pub fn duration(&self) -> f64 {
        f64::from(self.periods) / self.frequency
    }

    pub fn start(&self) -> Reference {
        self.at(0.0)
    }

    /// The reference at time t after the start, clamped to the oscillation's span (whole periods: the
    /// end state equals the start state).
    pub fn at(&self, t: f64) -> Reference {
        let w = self.omega();
        let phase = w * t.clamp(0.0, self.duration());
        Reference {
            position: self.mean - self.amplitude * phase.cos(),
            velocity: self.amplitude * w * phase.sin(),
            acceleration: self.amplitude * w * w * phase.cos(),
        }
    }
}

/// One part of a [`Trajectory`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Segment {
    Move(Quintic),
    Oscillate(Oscillation),
}

impl Segment {
    pub fn duration(&self) -> f64 {
        match self {
            Segment::Move(q) => q.duration(),
            Segment::Oscillate(o) => o.duration(),
        }
    }

    pub fn at(&self, t: f64) -> Reference {
        match self {
            Segment::Move(q) => q.at(t),
            Segment::Oscillate(o) => o.at(t),
        }
    }
}

/// Segments played one after another, all positions shifted by `offset` (so that a re-estimated surface
/// moves the whole plan without re-planning it). Past its end it holds the last segment's end.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    segments: Vec<Segment>,
    pub offset: f64,
}

impl Trajectory {
    /// `None` for a segment of non-positive or non-finite duration, or none at all.
    pub fn new(segments: Vec<Segment>) -> Option<Self> {
        let valid = |s: &Segment| s.duration().is_finite() && s.duration() > 0.0;
        (!segments.is_empty() && segments.iter().all(valid)).then_some(Self { segments, offset: 0.0 })
    }

    pub fn duration(&self) -> f64 {
        self.segments.iter().map(Segment::duration).sum()
    }

    pub fn at(&self, t: f64) -> Reference {
        let mut start = 0.0;
        for (i, s) in self.segments.iter().enumerate() {
            let end = start + s.duration();
            if t < end || i + 1 == self.segments.len() {
                let r = s.at(t - start);
                return Reference { position: r.position + self.offset, ..r };
            }
            start = end;
        }
        unreachable!("a trajectory has at least one segment")
    }
}
