//! A climbing gait: an inchworm of two tripods.
//!
//! Each end of the snake is a tripod of two links pressed across the gap, a zig-zag of three feet:
//! nodes 0 (left wall), 1 (right), 2 (left) at the bottom, nodes N−2 (left), N−1 (right), N (left) at the
//! top. The N−4 links between (the spine, bent as a regular arc to the side that keeps its nodes farther
//! from the walls: away from the left wall, which both its ends press) set the distance between the
//! tripods. A tripod squeezes itself — its middle joint's torque presses the middle foot
//! against the outer two, whose normal forces straddle it — so either tripod alone holds the snake with
//! three feet, whatever the weight's lever.
//!
//! Why not fewer links: rigid links pressed across a fixed gap have a fixed rise, so a grip moves only
//! with all its feet off the walls, and what holds the snake meanwhile must squeeze itself. A single link
//! across the gap (two feet) cannot: its squeeze is only what the weight's moment gives (f h = W x, a few
//! newtons here), and its feet slide. Hence N ≥ 6: two tripods and a spine of at least two links.
//!
//! One cycle (every step one set point, never fewer than three feet pressed):
//!
//! 1. release the top tripod's highest foot N (link N−1 turns steeper about the middle foot N−1), its
//!    lowest N−2 (link N−2 the same), then the middle one (the spine draws the tripod off the wall);
//! 2. stretch the spine: the top tripod rises by the step; press foot N−1, N−2, N (the reverse);
//! 3. release foot 2, 0 and 1 the same way; shorten the spine: the bottom tripod follows by the step;
//!    press foot 1, 0, 2.
//!
//! A tripod presses from its middle foot out: flattening the lower link about the middle foot moves the
//! low foot up the wall as it presses, flattening the upper one moves the high foot down, and the
//! friction this leaves in the two (down on one, up on the other) nearly cancels, so that the weight
//! shares the cone's room with little else. (Pressed from one end, every foot moved the same way and
//! its friction added to the weight's: the holding tripod's feet ended at the edge of their cones.)
//!
//! Every set point is a set of joint angles (the base is free); the poses below are only how they are
//! designed: where the snake goes is the equilibrium its squeeze reaches. Two corrections close the loop
//! on what it reached: the joint where the spine meets the holding tripod is commanded from that
//! tripod's actual turn ([`SetPoint::joints_from`]), and after each set point a small elastic change
//! evens out the feet's use of their cones ([`stability::rebalance`]).

use nalgebra::Vector2;
use serde::Serialize;
use softcontact_contact::{ContactModel, Kind, Tangential, TangentialLaw};
use softcontact_dynamics::PlanarChain;

use crate::Error;
use crate::snake::{FootForce, Snake, State};
use crate::stability::{self, DT, Settled, Stability};

/// The snake, its walls and its gait.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClimbConfig {
    /// Number of links N (≥ 6: two tripods of two links and a spine of at least two).
    pub links: usize,
    pub link_length: f64,
    pub link_mass: f64,
    /// The grips' angle from the horizontal when both their feet just touch \[rad\]: the gap is
    /// l cos(angle) + 2R.
    pub opening_angle: f64,
    /// The rubber feet: the snake paper's 1-inch gum-rubber half-ball (R, kₙ, kₜ) on sandpaper (μ).
    pub foot_radius: f64,
    pub normal_stiffness: f64,
    pub tangential_stiffness: f64,
    pub friction: f64,
    pub law: TangentialLaw,
    /// λ of the normal force's Hunt–Crossley damping and λₜ of the tangential one [N s/m^{5/2}].
    pub contact_damping: f64,
    pub tangential_damping: f64,
    pub kp: f64,
    pub kd: f64,
    /// How far past a wall a pressed foot's set point lies \[m\].
    pub squeeze: f64,
    /// How far from its wall a released foot's set point keeps it \[m\].
    pub clearance: f64,
    /// How far a grip moves up per cycle \[m\].
    pub step: f64,
    /// How high to climb \[m\].
    pub height: f64,
    /// How long a set point takes to move to the next (smoothly) \[s\].
    pub move_time: f64,
    /// The longest the snake is given to come to rest at a set point \[s\].
    pub settle_time: f64,
    /// Whether each set point is followed by a small change that evens out the feet's use of their
    /// friction cones ([`stability::rebalance`]).
    pub rebalance: bool,
}

impl Default for ClimbConfig {
    fn default() -> Self {
        // The snake paper's rubber: kₙ 8.506 N/mm^{3/2} and kₜ 4.05 N/mm^{3/2} (Table I and the linear paths), in
        // N/m^{3/2}.
        let per_mm = 1e3f64.powf(1.5);
        ClimbConfig {
            links: 6,
            link_length: 0.1,
            link_mass: 0.2,
            opening_angle: 60f64.to_radians(),
            foot_radius: 0.0127,
            normal_stiffness: 8.506 * per_mm,
            tangential_stiffness: 4.05 * per_mm,
            friction: 0.9,
            law: TangentialLaw::Walton,
            contact_damping: 3e5,
            tangential_damping: 3e5,
            kp: 400.0,
            kd: 1.0,
            squeeze: 2e-3,
            clearance: 3e-3,
            step: 0.008,
            height: 0.05,
            move_time: 0.3,
            settle_time: 3.0,
            rebalance: true,
        }
    }
}

impl ClimbConfig {
    /// The wall gap \[m\].
    pub fn gap(&self) -> f64 {
        self.link_length * self.opening_angle.cos() + 2.0 * self.foot_radius
    }

    /// The snake this configuration describes.
    pub fn snake(&self) -> Result<Snake, Error> {
        if self.links < 6 {
            return Err(Error::Config(format!(
                "{} links: the gait needs two tripods of two links and a spine of two (N ≥ 6; see the gait's documentation for why)",
                self.links
            )));
        }
        let positive = [
            ("friction", self.friction),
            ("normal_stiffness", self.normal_stiffness),
            ("link_length", self.link_length),
            ("link_mass", self.link_mass),
            ("foot_radius", self.foot_radius),
            ("kp", self.kp),
            ("step", self.step),
            ("move_time", self.move_time),
            ("settle_time", self.settle_time),
        ];
        if let Some((name, v)) = positive.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
            return Err(Error::Config(format!("{name} must be a finite number > 0 (got {v})")));
        }
        let non_negative =
            [("kd", self.kd), ("squeeze", self.squeeze), ("clearance", self.clearance), ("height", self.height)];
        if let Some((name, v)) = non_negative.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
            return Err(Error::Config(format!("{name} must be a finite number ≥ 0 (got {v})")));
        }
        if !(self.opening_angle > 0.0 && self.opening_angle < std::f64::consts::FRAC_PI_2) {
            return Err(Error::Config("the opening angle lies between 0° and 90°".into()));
        }
        let mut contact = ContactModel::new(Kind::HertzWalton, self.normal_stiffness, self.contact_damping)?;
        contact.tangential =
            Some(Tangential { stiffness: self.tangential_stiffness, friction: self.friction, law: self.law });
        contact.validate()?;
        Ok(Snake {
            chain: PlanarChain::uniform(self.links, self.link_length, self.link_mass),
            gap: self.gap(),
            feet: (0..=self.links).collect(),
            foot_radius: self.foot_radius,
            contact,
            tangential_damping: self.tangential_damping,
            kp: self.kp,
            kd: self.kd,
            loads: Vec::new(),
        })
    }
}

/// How many of a tripod's feet are off the walls: 0 (pressed), 1 (the highest off), 2 (the lowest too),
/// 3 (all, the middle one too).
type Off = usize;

/// One designed pose: how many feet each tripod has off the walls and the height of node N−1 above
/// node 1 (the tripods' middle feet, about which they turn) [m].
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pose {
    bottom: Off,
    top: Off,
    height: f64,
}

/// A set point of the gait: its name, the feet meant to press, its joint angles.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SetPoint {
    pub name: String,
    pub pressed: Vec<usize>,
    pub joints: Vec<f64>,
    /// The designed absolute angle of every link \[rad\].
    pub link_angles: Vec<f64>,
    /// The tripod that holds while the other moves (none for the first squeeze).
    pub holding: Option<Tripod>,
}

/// One end of the snake.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Tripod {
    Bottom,
    Top,
}

impl SetPoint {
    /// The joint angles to command from configuration `q`: the design, with the joint where the spine
    /// meets the holding tripod turned by how far that tripod's link actually turned from its design
    /// (its feet press less deep than designed, and the whole snake would swing by that angle, several
    /// millimetres at the far tripod — enough to miss the wall it is to press).
    pub fn joints_from(&self, q: &[f64], chain: &softcontact_dynamics::PlanarChain) -> Vec<f64> {
        let mut joints = self.joints.clone();
        let n = chain.links.len();
        let actual = chain.link_angles(q);
        match self.holding {
            // q₂ = φ₂ − φ₁: link 1 belongs to the bottom tripod, link 2 to the spine.
            Some(Tripod::Bottom) => joints[1] -= actual[1] - self.link_angles[1],
            // q_{N−2} = φ_{N−2} − φ_{N−3}: link N−2 belongs to the top tripod.
            Some(Tripod::Top) => joints[n - 3] += actual[n - 2] - self.link_angles[n - 2],
            None => {}
        }
        joints
    }
}

/// Designs the gait's set points for a configuration.
struct Planner<'a> {
    config: &'a ClimbConfig,
    gap: f64,
}

impl Planner<'_> {
    /// A tripod's three nodes, lowest first, its middle node (right wall) at `height`, with `off` feet
    /// off the walls: 1 the highest, 2 the lowest too, 3 all (the middle one as well).
    fn tripod(&self, off: Off, height: f64) -> Result<[Vector2<f64>; 3], Error> {
        let c = self.config;
        let (l, r, sq, cl) = (c.link_length, c.foot_radius, c.squeeze, c.clearance);
        let (right_pressed, right_off) = (self.gap - r + sq, self.gap - r - cl);
        // A pressed link reaches across the gap and a squeeze on either side; a link whose left foot is
        // off reaches two clearances less (its foot then clears the wall by a clearance or more).
        let pressed = self.gap - 2.0 * r + 2.0 * sq;
        let off_reach = self.gap - 2.0 * r - 2.0 * cl;
        if pressed >= l || off_reach - 3.0 * sq <= 0.0 {
            return Err(Error::Config(format!(
                "a link of {l} m cannot span the gap's {pressed:.4} m, or the clearance leaves it no room"
            )));
        }
        let rise = |reach: f64| (l * l - reach * reach).sqrt();
        // Alone on its wall (off = 2), the middle foot is pressed by the spine at the end of a long, compliant
        // lever: its set point goes three squeezes deeper, or it barely touches. Pressing the others moves
        // it back out along its normal only, which leaves its tangential force as it is.
        let middle_x = match off {
            // As far out again when it lets go, or the compliant lever keeps it on the wall.
            3 => right_off - 3.0 * sq,
            2 => right_pressed + 3.0 * sq,
            _ => right_pressed,
        };
        // Released, the links fold in by the middle foot's extra way out, so that their feet keep clear too.
        let released = off_reach - 3.0 * sq;
        let high_reach = match off {
            0 => pressed,
            1 | 2 => off_reach,
            _ => released,
        };
        let low_reach = match off {
            0 | 1 => pressed,
            2 => off_reach,
            _ => released,
        };
        let middle = Vector2::new(middle_x, height);
        let low = middle + Vector2::new(-low_reach, -rise(low_reach));
        let high = middle + Vector2::new(-high_reach, rise(high_reach));
        Ok([low, middle, high])
    }

    /// Node positions of a pose.
    fn nodes(&self, pose: Pose) -> Result<Vec<Vector2<f64>>, Error> {
        let n = self.config.links;
        let bottom = self.tripod(pose.bottom, 0.0)?;
        let top = self.tripod(pose.top, pose.height)?;
        let mut nodes = vec![bottom[0], bottom[1]];
        nodes.extend(self.spine(bottom[2], top[0], n - 4)?);
        nodes.extend([top[1], top[2]]);
        Ok(nodes)
    }

    /// The m spine links from `from` to `to` as a regular arc (every joint turned by the same angle), bent
    /// to the side that keeps its nodes farther from the walls: nodes `from` … `to`.
    fn spine(&self, from: Vector2<f64>, to: Vector2<f64>, m: usize) -> Result<Vec<Vector2<f64>>, Error> {
        let l = self.config.link_length;
        let chord = to - from;
        let d = chord.norm();
        if d >= m as f64 * l * (1.0 - 1e-9) {
            return Err(Error::Config(format!("the spine ({m} links of {l} m) cannot reach {d:.4} m")));
        }
        // d(ψ) = l sin(mψ/2)/sin(ψ/2) falls from m l at ψ = 0 to 0 at ψ = 2π/m.
        let length =
            |psi: f64| if psi == 0.0 { m as f64 * l } else { l * (m as f64 * psi / 2.0).sin() / (psi / 2.0).sin() };
        let (mut lo, mut hi) = (0.0, 2.0 * std::f64::consts::PI / m as f64);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if length(mid) > d { lo = mid } else { hi = mid }
        }
        let psi = 0.5 * (lo + hi);
        let heading = chord.y.atan2(chord.x);
        let r = self.config.foot_radius;
        let arc = |sign: f64| {
            let mut p = from;
            let mut out = vec![p];
            for k in 0..m {
                let a = heading - sign * psi * (m as f64 - 1.0) / 2.0 + sign * psi * k as f64;
                p += l * Vector2::new(a.cos(), a.sin());
                out.push(p);
            }
            // Replace the end by the target exactly (they agree to rounding).
            *out.last_mut().unwrap() = to;
            let clearance = out[1..m].iter().map(|p| (p.x - r).min(self.gap - r - p.x)).fold(f64::INFINITY, f64::min);
            (out, clearance)
        };
        let (a, b) = (arc(1.0), arc(-1.0));
        let (nodes, clearance) = if a.1 >= b.1 { a } else { b };
        if clearance < self.config.clearance {
            return Err(Error::Config(format!(
                "the spine bent to reach {d:.4} m comes within {:.1} mm of a wall: a smaller step or rise",
                clearance * 1e3
            )));
        }
        Ok(nodes)
    }

    /// The coordinates q of a pose's nodes; its set point is q[3..].
    fn coordinates(nodes: &[Vector2<f64>]) -> Vec<f64> {
        let angles: Vec<f64> = nodes.windows(2).map(|w| (w[1].y - w[0].y).atan2(w[1].x - w[0].x)).collect();
        let mut q = vec![nodes[0].x, nodes[0].y, angles[0]];
        for w in angles.windows(2) {
            let mut turn = w[1] - w[0];
            turn = (turn + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
            q.push(turn);
        }
        q
    }

    fn set_point(&self, name: String, pose: Pose, holding: Option<Tripod>) -> Result<SetPoint, Error> {
        let n = self.config.links;
        // Feet still pressed: the middle one, then the lowest, then the highest.
        let still = |off: Off, [low, middle, high]: [usize; 3]| [middle, low, high].into_iter().take(3 - off);
        let mut pressed: Vec<usize> = still(pose.bottom, [0, 1, 2]).chain(still(pose.top, [n - 2, n - 1, n])).collect();
        pressed.sort_unstable();
        let nodes = self.nodes(pose)?;
        let q = Self::coordinates(&nodes);
        let link_angles = nodes.windows(2).map(|w| (w[1].y - w[0].y).atan2(w[1].x - w[0].x)).collect();
        Ok(SetPoint { name, pressed, joints: q[3..].to_vec(), link_angles, holding })
    }
}

/// The gait's low height (node N−1 above node 1): the least at which every pose keeps the spine's nodes
/// `clearance` from the walls (the spine straightens as it rises). The high end, a step above, must fit
/// below the spine's full length.
fn low_height(planner: &Planner) -> Result<f64, Error> {
    let fits = |height: f64| {
        (0..=3).all(|off| {
            [(off, 0), (0, off)].iter().all(|&(bottom, top)| planner.nodes(Pose { bottom, top, height }).is_ok())
        })
    };
    let longest = planner.config.links as f64 * planner.config.link_length;
    let grid = |i: usize| longest * i as f64 / 1000.0;
    let first = (0..1000).map(grid).find(|&r| fits(r)).ok_or_else(|| {
        Error::Config("no spine rise keeps the spine off the walls: a wider opening angle or more links".into())
    })?;
    // The least fitting rise: bisect between the grid's last rise that does not fit and its first that does.
    let (mut lo, mut hi) = ((first - grid(1)).max(0.0), first);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if fits(mid) { hi = mid } else { lo = mid }
    }
    if !fits(hi + planner.config.step) {
        // The highest fitting height: bisect between the least and the grid's first height above it that
        // does not fit.
        let (mut top, mut beyond) = (hi, (0..=1000).map(grid).find(|&r| r > hi && !fits(r)).unwrap_or(longest));
        for _ in 0..60 {
            let mid = 0.5 * (top + beyond);
            if fits(mid) { top = mid } else { beyond = mid }
        }
        return Err(Error::Config(format!(
            "a step of {:.1} mm does not fit this snake between its walls: at most {:.1} mm (--step)",
            planner.config.step * 1e3,
            ((top - hi) * 1e4).floor() / 10.0
        )));
    }
    Ok(hi)
}

/// What happened at one set point of the climb.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SetPointReport {
    pub name: String,
    /// The joint angles commanded \[rad\].
    pub joints: Vec<f64>,
    /// The feet meant to press, and of them those pressed at the set point before too (meant to hold
    /// through the move).
    pub pressed: Vec<usize>,
    pub holding: Vec<usize>,
    /// Each foot's force, in the order of the feet along the chain.
    pub forces: Vec<FootForce>,
    /// The same as [fₙ ≥ 0, fₜ signed, positive up the wall] \[N\], in the order of the feet.
    pub contact_forces: Vec<[f64; 2]>,
    /// Each foot's cone margin 1 − |fₜ|/(μfₙ) (`None` off the walls).
    pub cone_margins: Vec<Option<f64>>,
    pub min_cone_margin: f64,
    /// The smallest cone margin of a foot meant to stay pressed through the move here.
    pub min_margin_on_the_way: f64,
    /// How far each foot slid along its wall on the way here and while settling \[m\].
    pub slip: Vec<f64>,
    /// Feet meant to stay pressed that slid farther than [`SLIP_TOLERANCE`].
    pub unintended_slides: Vec<usize>,
    /// Feet not meant to press that touched a wall at the equilibrium.
    pub unintended_contacts: Vec<usize>,
    pub settled: Settled,
    /// ‖G‖∞ at the equilibrium after Newton [N, N m].
    pub residual: f64,
    pub stability: Stability,
    /// Height of node 0 and of the centre of mass \[m\].
    pub foot_height: f64,
    pub com_height: f64,
    pub q: Vec<f64>,
    /// No fault ([`SetPointReport::faults`]): an equilibrium, stable, inside every cone (margin ≥
    /// `MIN_MARGIN`), and no foot slid or touched unintentionally.
    pub sound: bool,
}

impl SetPointReport {
    /// Why this set point is not sound, one reason per line (none when it is).
    pub fn faults(&self) -> Vec<String> {
        let mut out = Vec::new();
        let st = &self.stability;
        if self.residual > 1e-6 {
            out.push(if self.settled.at_rest {
                format!("no equilibrium found: at rest, but the static balance off by {:.2e}", self.residual)
            } else {
                format!(
                    "no equilibrium: still moving after {:.1} s (its feet sliding), the static balance off by {:.2e}",
                    self.settled.time, self.residual
                )
            });
            // What follows would describe a state in motion.
            return out;
        }
        if st.slowest.0 >= stability::STABLE_REAL_PART {
            out.push(format!(
                "not asymptotically stable: an eigenvalue {:+.3e} {:+.1}i s⁻¹ (needs < {:.0e})",
                st.slowest.0,
                st.slowest.1,
                stability::STABLE_REAL_PART
            ));
        }
        if st.return_distance > stability::RETURN_TOLERANCE {
            out.push(if st.return_speed < 1e-6 {
                format!(
                    "a start perturbed by {:.0e} comes to rest {:.1e} away, at a neighbouring equilibrium (a foot \
                     at its cone's edge slides, or the incremental law's microslip keeps what it took: friction \
                     with memory makes equilibria a continuum)",
                    stability::PERTURBATION,
                    st.return_distance
                )
            } else {
                format!(
                    "a start perturbed by {:.0e} is still {:.1e} from the equilibrium after {:.1} s",
                    stability::PERTURBATION,
                    st.return_distance,
                    st.return_time
                )
            });
        }
        for &f in &self.pressed {
            if self.forces[f].normal <= 0.0 {
                out.push(format!("foot {f} is meant to press and does not touch its wall"));
            }
        }
        for (f, m) in self.cone_margins.iter().enumerate() {
            if let Some(m) = m.filter(|m| *m < MIN_MARGIN) {
                let force = &self.forces[f];
                out.push(format!(
                    "foot {f} at the edge of its cone: margin {m:.3} < {MIN_MARGIN} (fₜ {:+.2} N, fₙ {:.2} N)",
                    force.tangential, force.normal
                ));
            }
        }
        for &f in &self.unintended_slides {
            out.push(format!("foot {f}, meant to hold, slid {:.2} mm", self.slip[f] * 1e3));
        }
        for &f in &self.unintended_contacts {
            out.push(format!("foot {f}, meant to be off, touches its wall with {:.2} N", self.forces[f].normal));
        }
        out
    }
}

/// The least cone margin a sound set point keeps: a tenth of the friction in reserve.
pub const MIN_MARGIN: f64 = 0.1;
/// The farthest a foot meant to hold may creep between two set points \[m\]: as a foot of a tripod lets
/// go, the load it carried moves to the others, and an unloading neighbour creeps a fraction of a
/// millimetre (reported per foot as `slip`).
pub const SLIP_TOLERANCE: f64 = 1e-3;

/// A climb: every set point's report and the height gained.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Climb {
    pub config: ClimbConfig,
    pub gap: f64,
    pub set_points: Vec<SetPointReport>,
    /// Height gained by node 0 and by the centre of mass from the first equilibrium to the last \[m\].
    pub climbed: f64,
    pub com_climbed: f64,
    /// Every set point sound and the height reached.
    pub success: bool,
}

fn com_height(snake: &Snake, q: &[f64]) -> f64 {
    let chain = &snake.chain;
    chain.links.iter().enumerate().map(|(k, l)| l.mass * chain.point(q, k, l.com).y).sum::<f64>() / chain.total_mass()
}

/// The snake on its way through a gait: its state, the set point it is commanded and the feet meant to
/// press.
pub struct Climber<'a> {
    pub snake: Snake,
    config: &'a ClimbConfig,
    pub state: State,
    commanded: Vec<f64>,
    pressed: Vec<usize>,
}

impl<'a> Climber<'a> {
    /// The snake of `config` placed with its feet just touching the walls, at rest, commanded to stay.
    pub fn new(config: &'a ClimbConfig) -> Result<Self, Error> {
        let snake = config.snake()?;
        let state = start(config, &snake)?;
        let commanded = state.q[3..].to_vec();
        Ok(Climber { snake, config, state, commanded, pressed: Vec::new() })
    }

    /// Moves to the set point (smoothly, over `move_time`), lets the snake settle, evens out its feet's
    /// use of their cones, and analyses the equilibrium it reached.
    pub fn go(&mut self, sp: &SetPoint) -> Result<SetPointReport, Error> {
        let (snake, config, state) = (&self.snake, self.config, &mut self.state);
        let mu = snake.friction();
        let current = &mut self.commanded;
        // Feet pressed before and after: they must hold (not slide) on the way.
        let holding: Vec<usize> = sp.pressed.iter().copied().filter(|f| self.pressed.contains(f)).collect();
        let mut joints = sp.joints_from(&state.q, &snake.chain);
        let mut min_on_the_way = 1.0f64;
        let mut slip = vec![0.0; state.feet.len()];
        let steps = (config.move_time / DT).round() as usize;
        for i in 1..=steps {
            let s = i as f64 / steps as f64;
            let blend = s * s * (3.0 - 2.0 * s);
            let target: Vec<f64> = current.iter().zip(&joints).map(|(a, b)| a + blend * (b - a)).collect();
            let forces = stability::step_counting_slip(snake, state, &target, &mut slip)?;
            for &f in &holding {
                min_on_the_way = min_on_the_way.min(forces[f].cone_margin(mu).unwrap_or(0.0));
            }
        }
        current.clone_from(&joints);
        let mut settled = stability::settle(snake, state, &joints, config.settle_time)?;
        for (s, more) in slip.iter_mut().zip(&settled.slip) {
            *s += more;
        }
        // Even out the feet's use of their cones while one is within 0.3 of its edge: small, elastic
        // changes of the set point (up to three), moved to like any other.
        for _ in 0..if config.rebalance && !sp.pressed.is_empty() { 3 } else { 0 } {
            stability::refine(snake, state, &joints)?;
            if stability::min_cone_margin(&snake.foot_forces(state, &joints)?, mu) >= 0.3 {
                break;
            }
            let balanced = stability::rebalance(snake, state, &joints, &sp.pressed)?;
            for i in 1..=steps {
                let s = i as f64 / steps as f64;
                let blend = s * s * (3.0 - 2.0 * s);
                let target: Vec<f64> = joints.iter().zip(&balanced).map(|(a, b)| a + blend * (b - a)).collect();
                let forces = stability::step_counting_slip(snake, state, &target, &mut slip)?;
                for &f in &holding {
                    min_on_the_way = min_on_the_way.min(forces[f].cone_margin(mu).unwrap_or(0.0));
                }
            }
            joints = balanced;
            current.clone_from(&joints);
            settled = stability::settle(snake, state, &joints, config.settle_time)?;
            for (s, more) in slip.iter_mut().zip(&settled.slip) {
                *s += more;
            }
        }
        let residual = stability::refine(snake, state, &joints)?;
        let forces = snake.foot_forces(state, &joints)?;
        let stability = stability::analyse(snake, state, &joints)?;
        let cone_margins: Vec<Option<f64>> = forces.iter().map(|f| f.cone_margin(mu)).collect();
        let min_cone_margin = stability::min_cone_margin(&forces, mu);
        // A foot meant to hold that slid farther than SLIP_TOLERANCE (a foot being placed settles).
        let unintended_slides: Vec<usize> = holding.iter().copied().filter(|&f| slip[f] > SLIP_TOLERANCE).collect();
        let unintended_contacts: Vec<usize> =
            (0..forces.len()).filter(|f| forces[*f].normal > 0.0 && !sp.pressed.contains(f)).collect();
        let report = SetPointReport {
            name: sp.name.clone(),
            joints: joints.clone(),
            pressed: sp.pressed.clone(),
            holding: holding.clone(),
            cone_margins,
            min_cone_margin,
            min_margin_on_the_way: min_on_the_way,
            slip: slip.clone(),
            unintended_slides,
            unintended_contacts,
            settled,
            residual,
            stability,
            foot_height: state.q[1],
            com_height: com_height(snake, &state.q),
            q: state.q.clone(),
            contact_forces: forces.iter().map(|f| [f.normal, f.tangential]).collect(),
            forces,
            sound: false,
        };
        let report = SetPointReport { sound: report.faults().is_empty(), ..report };
        self.pressed.clone_from(&sp.pressed);
        Ok(report)
    }
}

/// The gait's designer: the walls' gap and the spine's two heights.
struct Gait<'a> {
    planner: Planner<'a>,
    low: f64,
    high: f64,
}

impl<'a> Gait<'a> {
    fn new(config: &'a ClimbConfig) -> Result<Self, Error> {
        config.snake()?; // the configuration's checks, before any geometry
        let planner = Planner { config, gap: config.gap() };
        let low = low_height(&planner)?;
        Ok(Gait { planner, low, high: low + config.step })
    }

    /// The first set point: every foot pressed.
    fn squeeze(&self) -> Result<SetPoint, Error> {
        self.planner.set_point("squeeze".into(), Pose { bottom: 0, top: 0, height: self.low }, None)
    }

    /// The 14 set points of climbing cycle `c` (one step).
    fn cycle(&self, c: usize) -> Result<Vec<SetPoint>, Error> {
        let n = self.planner.config.links;
        let (low, high) = (self.low, self.high);
        let pose = |bottom, top, height| Pose { bottom, top, height };
        let up = format!("{:.0} mm", self.planner.config.step * 1e3);
        let mut steps = Vec::new();
        for (i, foot) in [n, n - 2, n - 1].into_iter().enumerate() {
            steps.push((format!("{c}: release foot {foot}"), pose(0, i + 1, low), Tripod::Bottom));
        }
        steps.push((format!("{c}: top tripod up {up}"), pose(0, 3, high), Tripod::Bottom));
        for (i, foot) in [n - 1, n - 2, n].into_iter().enumerate() {
            steps.push((format!("{c}: press foot {foot}"), pose(0, 2 - i, high), Tripod::Bottom));
        }
        for (i, foot) in [2, 0, 1].into_iter().enumerate() {
            steps.push((format!("{c}: release foot {foot}"), pose(i + 1, 0, high), Tripod::Top));
        }
        steps.push((format!("{c}: bottom tripod up {up}"), pose(3, 0, low), Tripod::Top));
        for (i, foot) in [1, 0, 2].into_iter().enumerate() {
            steps.push((format!("{c}: press foot {foot}"), pose(2 - i, 0, low), Tripod::Top));
        }
        steps.into_iter().map(|(name, p, holding)| self.planner.set_point(name, p, Some(holding))).collect()
    }
}

/// The gait's set points: the first squeeze, then `cycles` climbing cycles.
pub fn gait(config: &ClimbConfig, cycles: usize) -> Result<Vec<SetPoint>, Error> {
    let gait = Gait::new(config)?;
    let mut out = vec![gait.squeeze()?];
    for c in 1..=cycles {
        out.extend(gait.cycle(c)?);
    }
    Ok(out)
}

/// The snake placed with the squeeze's pose but its feet just touching the walls, at rest.
pub fn start(config: &ClimbConfig, snake: &Snake) -> Result<State, Error> {
    let low = low_height(&Planner { config, gap: config.gap() })?;
    let untouched = ClimbConfig { squeeze: 0.0, ..config.clone() };
    let planner = Planner { config: &untouched, gap: config.gap() };
    let nodes = planner.nodes(Pose { bottom: 0, top: 0, height: low })?;
    Ok(State::at_rest(snake, Planner::coordinates(&nodes)))
}

/// The first squeeze alone: the snake placed with its feet just touching, squeezed, and its equilibrium
/// analysed — how a set point (or a configuration) is judged without climbing.
pub fn squeeze(config: &ClimbConfig) -> Result<SetPointReport, Error> {
    Climber::new(config)?.go(&Gait::new(config)?.squeeze()?)
}

/// Climbs `config.height`: the squeeze, then cycles until node 0 has risen that far (each cycle gains
/// a little less than the step: the snake's compliance takes some back), at most three times the cycles
/// the step alone would need.
pub fn climb(config: &ClimbConfig) -> Result<Climb, Error> {
    let gait = Gait::new(config)?;
    let mut climber = Climber::new(config)?;
    let first = climber.go(&gait.squeeze()?)?;
    let (start_foot, start_com) = (first.foot_height, first.com_height);
    let mut reports = vec![first];
    let most = 3 * (config.height / config.step).ceil() as usize;
    let mut climbed = 0.0;
    for c in 1..=most {
        if climbed >= config.height {
            break;
        }
        for sp in gait.cycle(c)? {
            reports.push(climber.go(&sp)?);
        }
        climbed = reports.last().map_or(0.0, |r| r.foot_height - start_foot);
    }
    let com_climbed = reports.last().map_or(0.0, |r| r.com_height - start_com);
    let success = reports.iter().all(|r| r.sound) && climbed >= config.height;
    Ok(Climb { config: config.clone(), gap: climber.snake.gap, set_points: reports, climbed, com_climbed, success })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    /// Newton on the whole snake at every equilibrium, written out from the feet's forces as reported: the
    /// walls carry the weight (Σ fₜ = m g) and their normal forces cancel. (The base's rows of the balance
    /// Newton's method zeroed say the same: this checks the report against the solver.)
    fn assert_balanced(snake: &Snake, r: &SetPointReport) {
        let weight = snake.chain.total_mass() * snake.chain.gravity;
        let carried: f64 = r.forces.iter().map(|f| f.tangential).sum();
        assert!((carried - weight).abs() < 1e-6, "{}: the walls carry {carried} N of {weight} N", r.name);
        let push: f64 = r.forces.iter().map(|f| f.wall.map_or(0.0, |w| w.normal()) * f.normal).sum();
        assert!(push.abs() < 1e-6, "{}: the normal forces leave {push} N", r.name);
    }

    #[test]
    fn the_snake_climbs_two_cycles_with_every_set_point_sound() {
        let config = ClimbConfig { height: 0.016, ..ClimbConfig::default() };
        let climb = climb(&config).unwrap();
        let snake = config.snake().unwrap();
        let cycles = (climb.set_points.len() - 1) / 14;
        assert!(cycles >= 2 && climb.set_points.len() == 1 + 14 * cycles, "the squeeze and whole cycles");
        for r in &climb.set_points {
            assert!(r.sound, "{}: {:?}", r.name, r.faults());
            assert!(r.faults().is_empty());
            assert!(r.pressed.len() >= 3, "{}: three feet hold at every set point", r.name);
            assert!(r.residual < 1e-8, "{}: residual {}", r.name, r.residual);
            assert_balanced(&snake, r);
        }
        assert!(climb.climbed >= 0.016, "climbed {} m of 0.016", climb.climbed);
        assert!(climb.success);
        assert!((climb.com_climbed - climb.climbed).abs() < 2e-3, "the whole snake rose, not a foot");
    }

    /// A two-link chain — one tripod — squeezed by its joint: at the equilibrium the joint's PD torque
    /// balances, about the middle node, the wall's force on the top foot and the top link's weight
    /// (statics of the top link alone, written out from the geometry).
    #[test]
    fn a_tripod_balances_its_joint_torque_against_its_top_foot() {
        let config = ClimbConfig { links: 6, kp: 20.0, ..ClimbConfig::default() };
        let mut snake = config.snake().unwrap();
        snake.chain = softcontact_dynamics::PlanarChain::uniform(2, 0.1, 0.2);
        snake.feet = vec![0, 1, 2];
        let a = config.opening_angle;
        let r = config.foot_radius;
        let mut state = State::at_rest(&snake, vec![r, 0.0, a, std::f64::consts::PI - 2.0 * a]);
        let set_point = [std::f64::consts::PI - 2.0 * a + 0.05];
        stability::settle(&snake, &mut state, &set_point, 3.0).unwrap();
        let residual = stability::refine(&snake, &mut state, &set_point).unwrap();
        assert!(residual < 1e-10);
        let forces = snake.foot_forces(&state, &set_point).unwrap();
        assert!(forces.iter().all(|f| f.normal > 1.0 && f.cone_margin(snake.friction()).unwrap() > 0.0), "{forces:?}");
        let nodes = snake.chain.node_positions(&state.q);
        let top = &forces[2];
        let wall_force = Vector2::new(top.wall.unwrap().normal() * top.normal, top.tangential);
        let arm = nodes[2] - nodes[1];
        let com = (nodes[1] + nodes[2]) / 2.0 - nodes[1];
        let gravity = Vector2::new(0.0, -0.2 * snake.chain.gravity);
        let moment = arm.perp(&wall_force) + com.perp(&gravity);
        let torque = snake.kp * (set_point[0] - state.q[3]);
        assert!((torque + moment).abs() < 1e-9 * torque.abs().max(1.0), "joint {torque} N m against {moment} N m");
        let stability = stability::analyse(&snake, &state, &set_point).unwrap();
        assert!(stability.stable, "{stability:?}");
    }

    #[test]
    fn a_squeeze_too_weak_to_hold_is_found_and_explained() {
        // Set points that put the feet just on the walls: nothing squeezes, and the snake slides down.
        let config = ClimbConfig { squeeze: 0.0, ..ClimbConfig::default() };
        let report = squeeze(&config).unwrap();
        let faults = report.faults();
        assert!(!report.sound && faults[0].starts_with("no equilibrium: still moving"), "{faults:#?}");
    }

    /// Without contact damping only the joints' damping reaches the contact modes, through the chain:
    /// the slowest mode decays many times slower. With the joints' damping gone too, nothing is left.
    #[test]
    fn contact_damping_sets_how_fast_the_slowest_mode_decays() {
        let damped = squeeze(&ClimbConfig::default()).unwrap();
        let undamped =
            squeeze(&ClimbConfig { contact_damping: 0.0, tangential_damping: 0.0, ..ClimbConfig::default() }).unwrap();
        eprintln!(
            "slowest: {:?} with contact damping, {:?} without",
            damped.stability.slowest, undamped.stability.slowest
        );
        assert!(damped.sound);
        assert!(
            undamped.stability.slowest.0 > damped.stability.slowest.0 / 10.0,
            "at least ten times slower: {:?}",
            undamped.stability.slowest
        );
        let none =
            squeeze(&ClimbConfig { contact_damping: 0.0, tangential_damping: 0.0, kd: 0.0, ..ClimbConfig::default() })
                .unwrap();
        assert!(!none.stability.stable, "{:?}", none.stability);
        assert!(none.faults().iter().any(|f| f.starts_with("not asymptotically stable")), "{:?}", none.faults());
    }

    #[test]
    fn bad_configurations_are_refused_with_a_reason() {
        for (config, word) in [
            (ClimbConfig { links: 4, ..ClimbConfig::default() }, "N ≥ 6"),
            (ClimbConfig { kp: f64::NAN, ..ClimbConfig::default() }, "kp"),
            (ClimbConfig { step: 0.05, ..ClimbConfig::default() }, "does not fit"),
            (ClimbConfig { opening_angle: 0.0, ..ClimbConfig::default() }, "opening angle"),
        ] {
            let e = climb(&config).unwrap_err().to_string();
            assert!(e.contains(word), "{e}");
        }
    }
}
