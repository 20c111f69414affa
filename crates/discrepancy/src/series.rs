//! The recording as the workflow reads it: samples along the contact normal, checked.

use super::*;

/// Samples along the contact normal: time t \[s\], deformation z \[m\] from the contact position (negative in
/// free space), its rate ż [m/s] and the measured normal force f \[N\]; and the times \[s\] the sensor was
/// tared (a tare zeroes the sensor's drifted offset: [`softcontact_contact::EffectState::tare`]).
/// Optionally the rest of the wrench and pose, per sample, as the sensor effects read them
/// ([`SensorInputs`]): the tangential force \[N\] and the change of gravity along the normal since the last
/// tare [m/s²] (empty when not recorded: no crosstalk or tool weight can then be named).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub t: Vec<f64>,
    pub z: Vec<f64>,
    pub zdot: Vec<f64>,
    pub f: Vec<f64>,
    pub tares: Vec<f64>,
    pub tangential: Vec<[f64; 3]>,
    pub gravity_change: Vec<f64>,
    /// The whole wrench as the sensor read it, and the pose it needs, for the residual of every channel
    /// ([`Series::with_wrench`]).
    pub wrench: Option<Wrench>,
}

/// The fewest samples [`analyse`] accepts, in all and in contact.
pub const MIN_SAMPLES: usize = 50;
pub const MIN_CONTACT_SAMPLES: usize = 20;

impl Series {
    /// Checks equal lengths, finite values and strictly increasing time.
    pub fn new(t: Vec<f64>, z: Vec<f64>, zdot: Vec<f64>, f: Vec<f64>) -> Result<Self, DiscrepancyError> {
        let s = Series {
            t,
            z,
            zdot,
            f,
            tares: Vec::new(),
            tangential: Vec::new(),
            gravity_change: Vec::new(),
            wrench: None,
        };
        s.validate()?;
        Ok(s)
    }

    /// The same samples with the tangential force \[N\] and the change of gravity along the normal since the
    /// last tare [m/s²] of every sample (see [`SensorInputs`]).
    pub fn with_sensor_inputs(
        mut self,
        tangential: Vec<[f64; 3]>,
        gravity_change: Vec<f64>,
    ) -> Result<Self, DiscrepancyError> {
        self.tangential = tangential;
        self.gravity_change = gravity_change;
        self.validate()?;
        Ok(self)
    }

    /// The same samples with the whole wrench and the pose that predicts it (see [`Wrench`]).
    pub fn with_wrench(mut self, wrench: Wrench) -> Result<Self, DiscrepancyError> {
        wrench.validate(self.len())?;
        self.wrench = Some(wrench);
        Ok(self)
    }

    /// What the sensor effects read at sample i besides the normal force.
    pub fn inputs(&self, i: usize) -> SensorInputs {
        SensorInputs {
            tangential_force: self.tangential.get(i).copied().unwrap_or_default(),
            gravity_change: self.gravity_change.get(i).copied().unwrap_or_default(),
        }
    }

    /// The same samples with the sensor tared at these times \[s\] (any order; non-finite ones are refused).
    pub fn with_tares(mut self, mut tares: Vec<f64>) -> Result<Self, DiscrepancyError> {
        if let Some(index) = tares.iter().position(|x| !x.is_finite()) {
            return Err(DiscrepancyError::NonFinite { name: "tares", index });
        }
        tares.sort_by(f64::total_cmp);
        self.tares = tares;
        Ok(self)
    }

    /// Per sample: whether the sensor was tared since the previous sample (at or before the first one).
    pub fn tared_before(&self) -> Vec<bool> {
        let mut next = 0;
        self.t
            .iter()
            .map(|&t| {
                let before = next;
                while next < self.tares.len() && self.tares[next] <= t {
                    next += 1;
                }
                next > before
            })
            .collect()
    }

    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// The same samples with the surface moved `dz` deeper along the normal: z − dz.
    pub fn shifted(&self, dz: f64) -> Series {
        Series { z: self.z.iter().map(|z| z - dz).collect(), ..self.clone() }
    }

    pub fn validate(&self) -> Result<(), DiscrepancyError> {
        let n = self.t.len();
        if self.z.len() != n || self.zdot.len() != n || self.f.len() != n {
            return Err(DiscrepancyError::Lengths { t: n, z: self.z.len(), zdot: self.zdot.len(), f: self.f.len() });
        }
        for (name, len) in [("tangential", self.tangential.len()), ("gravity_change", self.gravity_change.len())] {
            if len != 0 && len != n {
                return Err(DiscrepancyError::InputLength { name, len, n });
            }
        }
        for (name, v) in [
            ("t", &self.t),
            ("z", &self.z),
            ("zdot", &self.zdot),
            ("f", &self.f),
            ("gravity_change", &self.gravity_change),
        ] {
            if let Some(index) = v.iter().position(|x| !x.is_finite()) {
                return Err(DiscrepancyError::NonFinite { name, index });
            }
        }
        if let Some(index) = self.tangential.iter().position(|x| !x.iter().all(|v| v.is_finite())) {
            return Err(DiscrepancyError::NonFinite { name: "tangential", index });
        }
        if let Some(i) = self.t.windows(2).position(|w| w[1] <= w[0]) {
            return Err(DiscrepancyError::Time(i + 1));
        }
        Ok(())
    }
}
