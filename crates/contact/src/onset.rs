//! Contact onset: where the surface is.
//!
//! A force threshold alone fires on a single noise spike, so contact is declared at the `confirm`-th
//! consecutive reading above the threshold (the snake paper: "the 3rd of three readings"), and the contact
//! position d is where the tool was at the first of those readings (the force-control paper: "the instant the normal
//! force goes above 1 N"). Contact ends after `confirm` consecutive readings below half the threshold.

use crate::ContactError;

/// Onset detector settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnsetConfig {
    /// Normal force above which a reading counts \[N\] (the force-control paper: 1 N).
    pub threshold: f64,
    /// Consecutive readings that confirm contact, or its loss (the snake paper: 3).
    pub confirm: usize,
}

impl Default for OnsetConfig {
    fn default() -> Self {
        Self { threshold: 1.0, confirm: 3 }
    }
}

/// What one reading changed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OnsetEvent {
    /// Contact confirmed; the contact position d is the tool position (along the contact normal) at the
    /// first reading above the threshold.
    Contact { position: f64 },
    /// Contact lost.
    Release,
}

/// Streaming onset detector over (position along the contact normal s = r·n, normal force f) readings.
#[derive(Debug, Clone)]
pub struct OnsetDetector {
    config: OnsetConfig,
    in_contact: bool,
    run: usize,
    first_position: f64,
    contact_position: Option<f64>,
}

impl OnsetDetector {
    pub fn new(config: OnsetConfig) -> Result<Self, ContactError> {
        if !(config.threshold.is_finite() && config.threshold > 0.0) || config.confirm == 0 {
            return Err(ContactError::InvalidConfig("onset threshold must be > 0 and confirm ≥ 1".into()));
        }
        Ok(Self { config, in_contact: false, run: 0, first_position: 0.0, contact_position: None })
    }

    pub fn in_contact(&self) -> bool {
        self.in_contact
    }

    /// The contact position of the current (or last) contact.
    pub fn contact_position(&self) -> Option<f64> {
        self.contact_position
    }

    /// Feeds one reading; non-finite readings are refused and change nothing.
    pub fn update(&mut self, position: f64, force: f64) -> Result<Option<OnsetEvent>, ContactError> {
        if !position.is_finite() || !force.is_finite() {
            return Err(ContactError::NonFinite {
                name: "onset reading",
                value: if position.is_finite() { force } else { position },
            });
        }
        if !self.in_contact {
            if force > self.config.threshold {
                if self.run == 0 {
                    self.first_position = position;
                }
                self.run += 1;
                if self.run >= self.config.confirm {
                    self.in_contact = true;
                    self.run = 0;
                    self.contact_position = Some(self.first_position);
                    return Ok(Some(OnsetEvent::Contact { position: self.first_position }));
                }
            } else {
                self.run = 0;
            }
        } else if force < 0.5 * self.config.threshold {
            self.run += 1;
            if self.run >= self.config.confirm {
                self.in_contact = false;
                self.run = 0;
                return Ok(Some(OnsetEvent::Release));
            }
        } else {
            self.run = 0;
        }
        Ok(None)
    }
}
