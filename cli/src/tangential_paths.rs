//! The tangential law of a recording with sideways motion in contact (`softcontact identify`).
//!
//! Each contact is an episode, its zero found as the snake paper finds it: at the third reading in a row above
//! 0.03 N along the normal, where the tool then is. Along an episode, δ_n is the tool's travel along the
//! normal from that zero, δ_t its travel across it along the episode's own tangential axis (the direction
//! of its largest sideways excursion), T the force on the hand against that axis. The normal force the
//! tangential law sees is Hertz's k_n (δ_n + z_0)^{3/2}, k_n and the zero's depth z_0 fitted to all episodes (the snake paper's eq. 4, its zero lies below the surface): a measured
//! force's noise would make the incremental law's slip test flicker. Both tangential laws are then fitted
//! and chosen by cross-validation over episodes (`softcontact_contact::identify_tangential`).

use nalgebra::{UnitQuaternion, Vector3};
use serde_json::json;
use softcontact_bag::Recording;
use softcontact_contact::{
    PathSample, TangentialIdentification, fit_normal_stiffness_and_zero, identify_tangential, thinned, with_hertz,
};
use softcontact_dynamics::lwr4;
use softcontact_msgs::geometry_msgs::{PoseStamped, WrenchStamped};
use softcontact_msgs::tf2_msgs::TFMessage;
use softcontact_nodes::geometry::{self, ContactGeometry};

use crate::identify_cmd::{POSE, TF_STATIC, WRENCH};
use crate::loading_paths_cmd::MAX_ZERO_DEPTH;

/// The snake paper's zero: the third reading in a row above this normal force \[N\].
pub const ZERO_THRESHOLD: f64 = 0.03;
/// An episode whose tool moved less than this across the normal carries no tangential law \[m\].
const MIN_SIDEWAYS: f64 = 20e-6;
/// Samples kept this far apart in the (δ_n, δ_t) plane \[m\].
const SPACING: f64 = 40e-6;

/// What the recording says about the tangential law.
#[derive(Debug)]
pub struct TangentialReport {
    /// Hertz's k_n fitted to every episode [N/m^{3/2}].
    pub k_n: f64,
    /// How far below the surface the zeros lie, fitted with k_n \[m\].
    pub zero_depth: f64,
    /// Episodes in contact, and those with sideways motion (the paths fitted).
    pub episodes: usize,
    pub identification: TangentialIdentification,
}

/// One reading in contact: the tool's position and the force on the hand, in the world.
#[derive(Clone, Copy)]
struct Reading {
    position: Vector3<f64>,
    force: Vector3<f64>,
}

/// The contact episodes of `recording` that move sideways, each from its zero with the measured normal
/// and tangential forces, thinned; and how many episodes there were in all.
pub fn episodes(recording: &Recording, normal: Vector3<f64>) -> anyhow::Result<(Vec<Vec<PathSample>>, usize)> {
    let mut tool_to_sensor = geometry::lwr4_tool_to_sensor().rotation;
    if recording.topic(TF_STATIC).is_some() {
        for m in recording.messages() {
            let m = m?;
            if m.topic() == TF_STATIC {
                let tf = m.decode::<TFMessage>()?;
                if let Some(r) = geometry::static_rotation(&[&tf], lwr4::TOOL_FRAME, lwr4::FT_SENSOR_FRAME) {
                    tool_to_sensor = r;
                }
                break;
            }
        }
    }
    let geometry = ContactGeometry::new(normal, tool_to_sensor)
        .ok_or_else(|| anyhow::anyhow!("the normal must be a finite, non-zero direction"))?;
    let mut pose: Option<(Vector3<f64>, UnitQuaternion<f64>)> = None;
    let (mut episodes, mut current, mut above, mut below) = (Vec::new(), Vec::<Reading>::new(), 0, 0);
    for m in recording.messages() {
        let m = m?;
        match m.topic() {
            POSE => pose = Some(geometry::pose_of(&m.decode::<PoseStamped>()?.pose)),
            WRENCH => {
                let Some((position, rotation)) = pose else { continue };
                let w = m.decode::<WrenchStamped>()?;
                let force = geometry.world_force(&rotation, &geometry::vector_of(&w.wrench.force));
                let p = geometry.normal_reading(&force);
                anyhow::ensure!(
                    p.is_finite() && position.iter().all(|v| v.is_finite()),
                    "a reading or pose that is no finite number at {} s",
                    w.header.stamp.as_secs_f64()
                );
                let in_contact = p > ZERO_THRESHOLD;
                (above, below) = if in_contact { (above + 1, 0) } else { (0, below + 1) };
                if !current.is_empty() || above >= 3 {
                    current.push(Reading { position, force });
                }
                if below >= 3 && !current.is_empty() {
                    episodes.push(std::mem::take(&mut current));
                }
            }
            _ => {}
        }
    }
    if !current.is_empty() {
        episodes.push(current);
    }
    let n = geometry.normal();
    // Each episode from its zero: (δ_n, δ_t along its axis, P and T measured).
    let mut paths: Vec<Vec<PathSample>> = Vec::new();
    for e in &episodes {
        let origin = e[0].position;
        let across = |r: &Reading| {
            let d = r.position - origin;
            d - n * d.dot(&n)
        };
        let axis = e.iter().map(across).max_by(|a, b| a.norm().total_cmp(&b.norm())).unwrap_or_default();
        if axis.norm() < MIN_SIDEWAYS {
            continue;
        }
        let axis = axis.normalize();
        let path: Vec<PathSample> = e
            .iter()
            .map(|r| PathSample {
                normal_displacement: (r.position - origin).dot(&n),
                tangential_displacement: across(r).dot(&axis),
                normal_force: geometry.normal_reading(&r.force),
                tangential_force: -r.force.dot(&axis),
            })
            .collect();
        paths.push(thinned(&path, SPACING));
    }
    Ok((paths, episodes.len()))
}

/// Reads `recording` for contact episodes and identifies the tangential law; `None` when fewer than two
/// move sideways.
pub fn from_recording(recording: &Recording, normal: Vector3<f64>) -> anyhow::Result<Option<TangentialReport>> {
    let (paths, episodes) = episodes(recording, normal)?;
    if paths.len() < 2 {
        return Ok(None);
    }
    let measured: Vec<(f64, f64)> = paths.iter().flatten().map(|s| (s.normal_displacement, s.normal_force)).collect();
    let (k_n, zero_depth) = fit_normal_stiffness_and_zero(&measured, MAX_ZERO_DEPTH)?;
    let paths = with_hertz(&paths, k_n, zero_depth);
    Ok(Some(TangentialReport { k_n, zero_depth, episodes, identification: identify_tangential(&paths, 5)? }))
}

fn fit_json(f: &softcontact_contact::TangentialFit) -> serde_json::Value {
    json!({
        "law": f.law.law.id(),
        "stiffness": f.law.stiffness,
        "friction": if f.friction_identified { json!(f.law.friction) } else { json!(null) },
        "friction_at_least": f.friction_at_least,
        "rms": f.rms,
        "cv_rms": f.cv_rms,
    })
}

pub fn to_json(r: &TangentialReport) -> serde_json::Value {
    let id = &r.identification;
    json!({
        "selected": id.chosen.id(),
        "k_n": r.k_n,
        "zero_depth": r.zero_depth,
        "episodes": r.episodes,
        "paths": id.paths,
        "samples": id.samples,
        "folds": id.folds,
        "walton": fit_json(&id.walton),
        "mindlin_deresiewicz": fit_json(&id.mindlin_deresiewicz),
    })
}

pub fn print(r: &TangentialReport) {
    let id = &r.identification;
    let per_mm = softcontact_contact::N_PER_MM_1_5;
    println!(
        "Tangential law: {} contact episodes, {} with sideways motion ({} samples), zero at the third reading above {} N; \
         Hertz k_n {:.3} N/mm^1.5 with the zero {:.1} µm below the surface",
        r.episodes,
        id.paths,
        id.samples,
        ZERO_THRESHOLD,
        r.k_n / per_mm,
        r.zero_depth * 1e6
    );
    println!("  {:<22}{:>16}{:>14}{:>12}{:>18}", "law", "k_t [N/mm^1.5]", "μ", "RMS [N]", "held-out RMS [N]");
    for (f, chosen) in [
        (&id.walton, id.chosen == id.walton.law.law),
        (&id.mindlin_deresiewicz, id.chosen == id.mindlin_deresiewicz.law.law),
    ] {
        let mu = if f.friction_identified {
            format!("{:.3}", f.law.friction)
        } else {
            format!("≥ {:.2}", f.friction_at_least)
        };
        println!(
            "  {:<22}{:>16.4}{:>14}{:>12.4}{:>18.4}{}",
            f.law.law.id(),
            f.law.stiffness / per_mm,
            mu,
            f.rms,
            f.cv_rms,
            if chosen { "  *" } else { "" }
        );
    }
    let why = match id.chosen {
        softcontact_contact::TangentialLaw::MindlinDeresiewicz => {
            "the force depends on the path taken (tangential_history): the incremental law predicts held-out paths better"
        }
        softcontact_contact::TangentialLaw::Walton => {
            "the path-independent law predicts held-out paths as well (straight paths from the zero cannot tell the laws apart)"
        }
    };
    println!("  selected: {} ({}-fold cross-validation over episodes): {why}", id.chosen.id(), id.folds);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loading_paths_cmd::tests::args;
    use crate::loading_paths_cmd::{LawArg, experiments};
    use softcontact_contact::TangentialLaw;

    /// The law `identify` names from each family's recording of `law`'s specimen (default bench errors).
    fn named(law: LawArg) -> Vec<Option<TangentialReport>> {
        let o = experiments(&args(law, 5.0, 0.5, 0.005)).unwrap();
        let dir = std::env::temp_dir().join(format!("softcontact-tangential-{}-{law:?}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let files = crate::loading_paths_record::write(&dir, &o.paths, &o.runs).unwrap();
        let names: Vec<_> = files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect();
        assert_eq!(names, ["normal.mcap", "linear.mcap", "two_segment.mcap"]);
        let reports = files
            .iter()
            .map(|f| from_recording(&Recording::open(f).unwrap(), Vector3::new(0.0, 0.0, -1.0)).unwrap())
            .collect();
        let _ = std::fs::remove_dir_all(&dir);
        reports
    }

    #[test]
    fn the_recordings_of_the_loading_paths_name_the_specimens_tangential_law() {
        let md = named(LawArg::MindlinDeresiewicz);
        // Normal loadings move nothing sideways: no tangential law to name.
        assert!(md[0].is_none());
        let two_segment = md[2].as_ref().unwrap();
        assert_eq!((two_segment.episodes, two_segment.identification.paths), (150, 150));
        assert_eq!(two_segment.identification.chosen, TangentialLaw::MindlinDeresiewicz, "{two_segment:?}");
        // k_t within the misalignment's bias (0.5° turns P into T: a few per cent high), k_n within 2 %.
        let k_t = two_segment.identification.mindlin_deresiewicz.law.stiffness / softcontact_contact::N_PER_MM_1_5;
        assert!((k_t / 3.7482 - 1.0).abs() < 0.08, "{k_t}");
        assert!(
            (two_segment.k_n / softcontact_contact::N_PER_MM_1_5 / 8.280 - 1.0).abs() < 0.02,
            "{}",
            two_segment.k_n
        );
        let walton = named(LawArg::Walton);
        for r in &walton[1..] {
            assert_eq!(r.as_ref().unwrap().identification.chosen, TangentialLaw::Walton, "{r:?}");
        }
    }
}
