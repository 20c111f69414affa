//! The kinematic tree of a serial chain, built from a URDF.
//!
//! Fixed joints are folded away: a link attached through fixed joints becomes a [`Frame`] of the moving
//! body it rides on, and its inertia is added to that body. What remains is one [`Joint`] per degree of
//! freedom, each with a constant placement in its parent joint's frame, an axis and a body inertia.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};

use crate::Error;

/// Standard gravity, pointing down the world z axis (world z is up).
pub const STANDARD_GRAVITY: Vector3<f64> = Vector3::new(0.0, 0.0, -9.81);

/// Index of a frame in [`Model::frames`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FrameId(pub usize);

/// Limits of one joint as the URDF states them (SI units; ±∞ for a continuous joint's position).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    pub lower: f64,
    pub upper: f64,
    pub velocity: f64,
    pub effort: f64,
}

/// Mass properties of a rigid body about its own frame origin: mass m, first moment h = m·c and the
/// rotational inertia about the origin. Origin-based so that the recursions need no COM shifts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyInertia {
    pub mass: f64,
    pub first_moment: Vector3<f64>,
    pub inertia_origin: Matrix3<f64>,
}

impl BodyInertia {
    pub const ZERO: Self = Self {
        mass: 0.0,
        first_moment: Vector3::new(0.0, 0.0, 0.0),
        inertia_origin: Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    };

    /// From mass, centre of mass and inertia about the centre of mass, all in the body frame.
    pub fn from_com(mass: f64, com: Vector3<f64>, inertia_com: Matrix3<f64>) -> Self {
        let c = com.cross_matrix();
        Self { mass, first_moment: mass * com, inertia_origin: inertia_com - mass * c * c }
    }

    /// Centre of mass in the body frame (origin for a massless body).
    pub fn com(&self) -> Vector3<f64> {
        if self.mass > 0.0 { self.first_moment / self.mass } else { Vector3::zeros() }
    }

    /// The same body described in a parent frame, where `placement` maps body coordinates to parent ones.
    pub fn expressed_in_parent(&self, rotation: &Matrix3<f64>, translation: &Vector3<f64>) -> Self {
        let h = rotation * self.first_moment;
        let p = translation;
        // Parallel-axis shift of an origin-based inertia: −m[p]×² − [p]×[h]× − [h]×[p]×, written with
        // [a]×[b]× = b aᵀ − (a·b) 1 as rank-one terms (a third of the work of the matrix products).
        let shift = Matrix3::from_diagonal_element(self.mass * p.norm_squared() + 2.0 * p.dot(&h))
            - (self.mass * p + h) * p.transpose()
            - p * h.transpose();
        Self {
            mass: self.mass,
            first_moment: h + self.mass * p,
            inertia_origin: rotation * self.inertia_origin * rotation.transpose() + shift,
        }
    }

    pub fn add(&self, other: &Self) -> Self {
        Self {
            mass: self.mass + other.mass,
            first_moment: self.first_moment + other.first_moment,
            inertia_origin: self.inertia_origin + other.inertia_origin,
        }
    }
}

/// One degree of freedom: a revolute joint and the rigid body it moves.
#[derive(Debug, Clone)]
pub struct Joint {
    pub name: String,
    pub limits: JointLimits,
    /// Rotation of the joint frame (at q = 0) in the parent joint's frame (world for the first joint).
    pub(crate) rotation: Matrix3<f64>,
    pub(crate) rotation_is_identity: bool,
    /// Origin of the joint frame in the parent joint's frame.
    pub(crate) translation: Vector3<f64>,
    /// Unit rotation axis in the joint frame.
    pub(crate) axis: Vector3<f64>,
    /// Everything rigidly attached to this joint's child link, in the joint frame.
    pub(crate) body: BodyInertia,
}

impl Joint {
    pub fn axis(&self) -> Vector3<f64> {
        self.axis
    }
    pub fn body(&self) -> &BodyInertia {
        &self.body
    }
}

/// A named frame (one per URDF link) rigidly attached to a joint's body, or to the world.
#[derive(Debug, Clone)]
pub struct Frame {
    pub name: String,
    /// The joint whose body carries the frame; `None` for frames fixed to the world.
    pub joint: Option<usize>,
    /// Pose of the frame in that joint's frame (or in the world).
    pub placement: Isometry3<f64>,
}

/// A serial chain of revolute joints with named frames: the robot as the dynamics sees it.
#[derive(Debug, Clone)]
pub struct Model {
    pub name: String,
    pub joints: Vec<Joint>,
    pub frames: Vec<Frame>,
    /// Gravity acceleration in world coordinates.
    pub gravity: Vector3<f64>,
    frame_ids: HashMap<String, FrameId>,
}

fn pose_to_isometry(pose: &urdf_rs::Pose) -> Isometry3<f64> {
    let [x, y, z] = pose.xyz.0;
    let [roll, pitch, yaw] = pose.rpy.0;
    // URDF rpy: fixed-axis roll about x, then pitch about y, then yaw about z.
    Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_euler_angles(roll, pitch, yaw))
}

fn link_inertia(link: &urdf_rs::Link) -> Result<BodyInertia, Error> {
    let inertial = &link.inertial;
    let i = &inertial.inertia;
    let inertia_com = Matrix3::new(i.ixx, i.ixy, i.ixz, i.ixy, i.iyy, i.iyz, i.ixz, i.iyz, i.izz);
    let mass = inertial.mass.value;
    let finite = mass.is_finite() && inertia_com.iter().all(|v| v.is_finite());
    let eig = inertia_com.symmetric_eigenvalues();
    // A physical inertia tensor is positive semi-definite and its principal moments obey the triangle
    // inequality; a tolerance admits rounding in the file.
    let tol = 1e-9 * eig.amax().max(1e-12);
    let physical = finite
        && mass >= 0.0
        && eig.iter().all(|&e| e >= -tol)
        && eig[0] + eig[1] + tol >= eig[2]
        && eig[1] + eig[2] + tol >= eig[0]
        && eig[0] + eig[2] + tol >= eig[1];
    if !physical {
        return Err(Error::NonPhysicalInertia { link: link.name.clone() });
    }
    let origin = pose_to_isometry(&inertial.origin);
    let rot = origin.rotation.to_rotation_matrix().into_inner();
    Ok(BodyInertia::from_com(mass, origin.translation.vector, rot * inertia_com * rot.transpose()))
}

/// Mass properties of a link and everything attached below it through fixed joints, in that link's
/// frame: e.g. the tool beyond an F/T sensor, whose weight the sensor reads.
pub fn fixed_subtree_inertia(robot: &urdf_rs::Robot, link: &str) -> Result<BodyInertia, Error> {
    let links: HashMap<&str, &urdf_rs::Link> = robot.links.iter().map(|l| (l.name.as_str(), l)).collect();
    let root = links.get(link).ok_or_else(|| Error::UnknownFrame {
        name: link.to_string(),
        known: robot.links.iter().map(|l| l.name.as_str()).collect::<Vec<_>>().join(", "),
    })?;
    let mut total = link_inertia(root)?;
    let mut stack = vec![(link.to_string(), Isometry3::identity())];
    while let Some((name, pose)) = stack.pop() {
        for joint in robot.joints.iter().filter(|j| j.parent.link == name) {
            if !matches!(joint.joint_type, urdf_rs::JointType::Fixed) {
                return Err(Error::UnsupportedJoint {
                    joint: joint.name.clone(),
                    kind: "movable inside a fixed tool".into(),
                });
            }
            let child_pose = pose * pose_to_isometry(&joint.origin);
            let child = links
                .get(joint.child.link.as_str())
                .ok_or_else(|| Error::MissingLink { joint: joint.name.clone(), link: joint.child.link.clone() })?;
            let rot = child_pose.rotation.to_rotation_matrix().into_inner();
            total = total.add(&link_inertia(child)?.expressed_in_parent(&rot, &child_pose.translation.vector));
            stack.push((joint.child.link.clone(), child_pose));
        }
    }
    Ok(total)
}

/// The largest URDF read [bytes]: a robot description is a few tens of kB (urdf/lwr4.urdf: 7 kB).
const MAX_URDF_BYTES: u64 = 4 << 20;

impl Model {
    /// Reads and builds the model from a URDF file: a regular file (not a device or a FIFO) of at most
    /// 4 MB (a robot description is tens of kB: a larger file is refused, not read).
    pub fn from_urdf_file(path: impl AsRef<Path>) -> Result<Self, Error> {
        use std::io::Read;
        let path = path.as_ref();
        let read_error = |message: String| Error::Read { path: path.display().to_string(), message };
        let meta = std::fs::metadata(path).map_err(|e| read_error(e.to_string()))?;
        if !meta.is_file() {
            return Err(read_error("not a regular file".into()));
        }
        let too_large = || read_error(format!("larger than {} MB: not a robot description", MAX_URDF_BYTES >> 20));
        if meta.len() > MAX_URDF_BYTES {
            return Err(too_large());
        }
        // The file may grow after the check: read no more than the bound.
        let mut text = String::new();
        std::fs::File::open(path)
            .and_then(|f| f.take(MAX_URDF_BYTES + 1).read_to_string(&mut text))
            .map_err(|e| read_error(e.to_string()))?;
        if text.len() as u64 > MAX_URDF_BYTES {
            return Err(too_large());
        }
        Self::from_urdf_str(&text).map_err(|e| {
            if let Error::Parse(m) = e { Error::Read { path: path.display().to_string(), message: m } } else { e }
        })
    }

    /// Builds the model from URDF text.
    pub fn from_urdf_str(text: &str) -> Result<Self, Error> {
        let robot = urdf_rs::read_from_string(text).map_err(|e| Error::Parse(e.to_string()))?;
        Self::from_urdf(&robot)
    }

    /// Builds the model from a parsed URDF. The tree must be a single serial chain of revolute (or
    /// continuous) joints; fixed joints may branch off anywhere and become frames.
    pub fn from_urdf(robot: &urdf_rs::Robot) -> Result<Self, Error> {
        let UrdfTree { links, children, root } = UrdfTree::of(robot)?;
        // Which links have a movable joint somewhere below them: decides the one branch the chain follows.
        fn movable_below(link: &str, children: &HashMap<&str, Vec<&urdf_rs::Joint>>) -> bool {
            children.get(link).is_some_and(|js| {
                js.iter().any(|j| {
                    !matches!(j.joint_type, urdf_rs::JointType::Fixed) || movable_below(&j.child.link, children)
                })
            })
        }

        let mut model = Model {
            name: robot.name.clone(),
            joints: Vec::new(),
            frames: Vec::new(),
            gravity: STANDARD_GRAVITY,
            frame_ids: HashMap::new(),
        };
        // Depth-first walk. `owner` is the joint whose body carries the current link, and `placement`
        // the link's pose in that joint's frame (world when there is no owner yet).
        let mut stack = vec![(root, None::<usize>, Isometry3::identity())];
        while let Some((link_name, owner, placement)) = stack.pop() {
            let link = links[link_name];
            model.add_frame(link_name, owner, placement);
            if let Some(j) = owner {
                let inertia = link_inertia(link)?;
                let rot = placement.rotation.to_rotation_matrix().into_inner();
                model.joints[j].body =
                    model.joints[j].body.add(&inertia.expressed_in_parent(&rot, &placement.translation.vector));
            }
            let kids = children.get(link_name).map(Vec::as_slice).unwrap_or(&[]);
            let moving: Vec<&str> = kids
                .iter()
                .filter(|j| {
                    !matches!(j.joint_type, urdf_rs::JointType::Fixed) || movable_below(&j.child.link, &children)
                })
                .map(|j| j.name.as_str())
                .collect();
            if moving.len() > 1 {
                return Err(Error::NotASerialChain {
                    link: link_name.to_string(),
                    branches: moving.iter().map(|s| s.to_string()).collect(),
                });
            }
            for joint in kids.iter().rev() {
                let origin = pose_to_isometry(&joint.origin);
                match joint.joint_type {
                    urdf_rs::JointType::Fixed => stack.push((joint.child.link.as_str(), owner, placement * origin)),
                    urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => {
                        model.joints.push(revolute_joint(joint, placement * origin)?);
                        stack.push((joint.child.link.as_str(), Some(model.joints.len() - 1), Isometry3::identity()));
                    }
                    ref other => {
                        return Err(Error::UnsupportedJoint {
                            joint: joint.name.clone(),
                            kind: format!("{other:?}").to_lowercase(),
                        });
                    }
                }
            }
        }
        if model.joints.is_empty() {
            return Err(Error::NoMovableJoint);
        }
        if let Some(j) = model.joints.iter().find(|j| j.body.mass <= 0.0) {
            return Err(Error::NoInertial { joint: j.name.clone() });
        }
        Ok(model)
    }

    fn add_frame(&mut self, name: &str, joint: Option<usize>, placement: Isometry3<f64>) {
        self.frame_ids.insert(name.to_string(), FrameId(self.frames.len()));
        self.frames.push(Frame { name: name.to_string(), joint, placement });
    }

    /// This robot carrying `payload` (mass properties in `frame`'s coordinates) rigidly on the body that
    /// carries `frame`: a load its description does not know — an adapter plate, cables, a tool heavier
    /// than the URDF says — as a simulator hides one. Fails for a frame fixed to the world.
    pub fn with_payload(&self, frame: FrameId, payload: &BodyInertia) -> Result<Model, Error> {
        let f = self.frame(frame);
        let joint = f.joint.ok_or_else(|| Error::Parse(format!("frame `{}` is fixed to the world", f.name)))?;
        let (rotation, translation) =
            (f.placement.rotation.to_rotation_matrix().into_inner(), f.placement.translation.vector);
        let mut model = self.clone();
        let body = &mut model.joints[joint].body;
        *body = body.add(&payload.expressed_in_parent(&rotation, &translation));
        Ok(model)
    }

    /// Number of degrees of freedom.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// The frame of a URDF link, by name.
    pub fn frame_id(&self, name: &str) -> Result<FrameId, Error> {
        self.frame_ids.get(name).copied().ok_or_else(|| Error::UnknownFrame {
            name: name.to_string(),
            known: self.frames.iter().map(|f| f.name.as_str()).collect::<Vec<_>>().join(", "),
        })
    }

    pub fn frame(&self, id: FrameId) -> &Frame {
        &self.frames[id.0]
    }

    /// Total mass of the moving bodies.
    pub fn moving_mass(&self) -> f64 {
        self.joints.iter().map(|j| j.body.mass).sum()
    }
}

/// A revolute or continuous joint placed at `in_parent` in its parent's frame, its body still empty.
fn revolute_joint(joint: &urdf_rs::Joint, in_parent: Isometry3<f64>) -> Result<Joint, Error> {
    if joint.mimic.is_some() {
        return Err(Error::UnsupportedJoint { joint: joint.name.clone(), kind: "mimic".into() });
    }
    let axis = Vector3::from(joint.axis.xyz.0);
    let norm = axis.norm();
    if !(norm.is_finite() && norm > 1e-12) {
        return Err(Error::ZeroAxis { joint: joint.name.clone() });
    }
    let continuous = matches!(joint.joint_type, urdf_rs::JointType::Continuous);
    let l = &joint.limit;
    Ok(Joint {
        name: joint.name.clone(),
        limits: JointLimits {
            lower: if continuous { f64::NEG_INFINITY } else { l.lower },
            upper: if continuous { f64::INFINITY } else { l.upper },
            velocity: l.velocity,
            effort: l.effort,
        },
        rotation: in_parent.rotation.to_rotation_matrix().into_inner(),
        rotation_is_identity: in_parent.rotation.to_rotation_matrix().into_inner() == Matrix3::identity(),
        translation: in_parent.translation.vector,
        axis: axis / norm,
        body: BodyInertia::ZERO,
    })
}

/// A URDF's links by name, each link's child joints, and the one root link: checked to be a tree.
struct UrdfTree<'a> {
    links: HashMap<&'a str, &'a urdf_rs::Link>,
    children: HashMap<&'a str, Vec<&'a urdf_rs::Joint>>,
    root: &'a str,
}

impl<'a> UrdfTree<'a> {
    fn of(robot: &'a urdf_rs::Robot) -> Result<Self, Error> {
        let links: HashMap<&str, &urdf_rs::Link> = robot.links.iter().map(|l| (l.name.as_str(), l)).collect();
        let mut children: HashMap<&str, Vec<&urdf_rs::Joint>> = HashMap::new();
        let mut is_child: HashMap<&str, bool> = HashMap::new();
        for joint in &robot.joints {
            for link in [&joint.parent.link, &joint.child.link] {
                if !links.contains_key(link.as_str()) {
                    return Err(Error::MissingLink { joint: joint.name.clone(), link: link.clone() });
                }
            }
            if is_child.insert(joint.child.link.as_str(), true).is_some() {
                return Err(Error::NotATree { link: joint.child.link.clone() });
            }
            children.entry(joint.parent.link.as_str()).or_default().push(joint);
        }
        let roots: Vec<&str> =
            robot.links.iter().map(|l| l.name.as_str()).filter(|n| !is_child.contains_key(n)).collect();
        let root = match roots.as_slice() {
            [root] => *root,
            [] => {
                return Err(Error::NotATree { link: robot.links.first().map(|l| l.name.clone()).unwrap_or_default() });
            }
            _ => return Err(Error::ManyRoots(roots.iter().map(|s| s.to_string()).collect())),
        };
        Ok(Self { links, children, root })
    }
}
