//! The force-control paper's published numbers (the KUKA LWR IV on a real sponge and dice), printed beside ours.

pub struct PaperSurface {
    /// Table I: fitness mean and standard deviation of Kelvin-Voigt, Hunt-Crossley, Azad-Featherstone.
    pub fitness: [(f64, f64); 3],
    /// The maximum normal force of the identification experiments \[N\].
    pub max_force: f64,
    /// Tables II/III: |command − actual| \[N\] per cycle and command (cycles 1–4: the first six ratios,
    /// cycle 5: the second six).
    pub errors: [[f64; 6]; 5],
}

pub const SPONGE: PaperSurface = PaperSurface {
    fitness: [(0.965, 0.001), (0.981, 0.001), (0.986, 0.001)],
    max_force: 280.0,
    errors: [
        [30.49, 14.33, 15.25, 13.56, 17.46, 15.93],
        [15.45, 4.92, 9.47, 7.43, 12.45, 13.16],
        [16.02, 5.38, 11.69, 6.33, 11.56, 13.70],
        [18.01, 5.10, 12.59, 5.47, 10.72, 13.69],
        [17.23, 5.30, 14.06, 6.23, 12.80, 13.09],
    ],
};

pub const DICE: PaperSurface = PaperSurface {
    fitness: [(0.976, 0.001), (0.845, 0.002), (0.853, 0.002)],
    max_force: 130.0,
    errors: [
        [15.81, 8.02, 8.73, 9.62, 9.67, 7.42],
        [2.26, 1.51, 2.89, 5.61, 5.39, 3.57],
        [7.13, 0.95, 3.49, 4.04, 4.72, 3.85],
        [8.30, 0.10, 3.94, 3.38, 4.51, 3.43],
        [6.65, 1.58, 4.56, 5.30, 5.97, 4.59],
    ],
};
