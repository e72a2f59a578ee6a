//! Equations of state for the pressure of weakly compressible materials.
//!
//! * `Linear` — paper 000 eq. 4: p = K (rho / rho0 - 1) = K (1 / J - 1).
//! * `Tait` — paper 001 eqs. 6, 31: p = (K / gamma) (exp(-gamma eps_v) - 1), eps_v = J - 1.
//!
//! Both have tangent bulk modulus K at J = 1; pressure is positive in compression.

use crate::real::{r, Real};
use serde::Deserialize;

#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Eos {
    Linear,
    Tait {
        #[serde(default = "default_gamma")]
        gamma: f64,
    },
}

fn default_gamma() -> f64 {
    7.0
}

impl Default for Eos {
    fn default() -> Self {
        Eos::Linear
    }
}

impl Eos {
    /// Pressure (positive in compression) at volume ratio `j` for bulk modulus `k`.
    #[inline]
    pub fn pressure(&self, k: Real, j: Real) -> Real {
        match *self {
            Eos::Linear => k * (r(1.0) / j - r(1.0)),
            Eos::Tait { gamma } => {
                let g = r(gamma);
                k / g * ((-g * (j - r(1.0))).exp() - r(1.0))
            }
        }
    }

    /// Tangent bulk modulus -dp/d(eps_v) at `j`, for stability estimates.
    #[inline]
    pub fn tangent_bulk(&self, k: Real, j: Real) -> Real {
        match *self {
            Eos::Linear => k / (j * j),
            Eos::Tait { gamma } => k * (-r(gamma) * (j - r(1.0))).exp(),
        }
    }
}
