//! The augmentation terms of a model structure ([`crate::fit::Structure`]): what each adds to the design,
//! one column (one linear amplitude) at a fixed shape.

/// An augmentation term with its shape parameter fixed; each adds one column (one linear amplitude).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Term {
    /// 1 over all samples; coefficient offset [N].
    Bias,
    /// Time since the last tare over all samples; coefficient rate [N/s].
    SensorDrift,
    /// Maxwell branch of unit stiffness and time constant τ [s]; coefficient k_m [N/m].
    Relax(f64),
    /// Quasi-linear branch: driven by zᵃ instead of z, time constant τ [s]; coefficient g·k.
    QuasiRelax(f64),
    /// zᵃ·tanh(ż/v₀) with v₀ [m/s]; coefficient k·h [N/mᵃ].
    Hyst(f64),
    /// −a·zᵃ⁻¹ (linearised shift of the surface position); coefficient k·δz₀. Always in the structure: the
    /// contact position is refitted with every candidate, so that no effect absorbs an error of the onset.
    Shift,
    /// −t·a·zᵃ⁻¹ (linearised surface-zero drift); coefficient k·r.
    OffsetLin,
    /// zᵃ·ln z (linearised change of the stiffness exponent); coefficient k·δa.
    ExpDeriv,
    /// The tangential force along the recording's lateral axis [N]; coefficient the crosstalk coupling.
    Crosstalk,
    /// The tangential force along the second lateral axis, across the first in the surface's plane, where
    /// the record loads that way too ([`Data::second_axis`]); coefficient the coupling along it.
    CrosstalkSecond,
    /// The change of gravity along the normal since the last tare [m/s²]; coefficient the unknown mass [kg].
    Gravity,
    /// Minus the share of an adhesion's pull-off force with range δ [m] ([`softcontact_contact::Effect::Adhesion`]);
    /// coefficient the pull-off force [N].
    Adhesion(f64),
    /// The hand's rate along the normal less its rate while the sensor's zero was read [m/s] ([`Data::drag_rate`]),
    /// in contact and out of it; coefficient the medium's drag [N·s/m].
    Drag,
    /// ż·δ/(gap + δ), gap = max(−z, 0), with the reach δ [m] ([`softcontact_contact::Effect::SqueezeFilm`]);
    /// coefficient the film's damping in contact [N·s/m].
    Squeeze(f64),
}

impl Term {
    /// A term of the sensor alone: it acts out of contact too.
    pub(crate) fn of_sensor(self) -> bool {
        matches!(
            self,
            Term::Bias
                | Term::SensorDrift
                | Term::Crosstalk
                | Term::CrosstalkSecond
                | Term::Gravity
                | Term::Drag
                | Term::Squeeze(_)
        )
    }

    /// A term the law's clamp at zero leaves alone: the sensor's, and an adhesion, which pulls on what the
    /// clamped law gives and beyond the surface.
    pub(crate) fn unclamped(self) -> bool {
        self.of_sensor() || matches!(self, Term::Adhesion(_))
    }
}
