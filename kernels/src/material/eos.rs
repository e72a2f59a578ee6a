//! Equations of state for the pressure of weakly compressible materials.
//!
//! * `Linear` — paper 000 eq. 4: p = K (rho / rho0 - 1) = K (1 / J - 1).
//! * `Tait` — paper 001 eqs. 6, 31: p = (K / gamma) (exp(-gamma eps_v) - 1), eps_v = J - 1.
//!
//! Both have tangent bulk modulus K at J = 1; pressure is positive in compression.

use crate::material::MaterialError;
use crate::real::{r, Real, M3};
use serde::Deserialize;

#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Eos {
    #[default]
    Linear,
    Tait {
        #[serde(default = "default_gamma")]
        gamma: f64,
    },
}

fn default_gamma() -> f64 {
    7.0
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

    /// Adjoint of [`Eos::pressure`]: the adjoints `(k_bar, j_bar)` of its inputs for the adjoint
    /// `p_bar` of the pressure.
    #[inline]
    pub fn pressure_adjoint(&self, k: Real, j: Real, p_bar: Real) -> (Real, Real) {
        match *self {
            Eos::Linear => (p_bar * (r(1.0) / j - r(1.0)), -p_bar * k / (j * j)),
            Eos::Tait { gamma } => {
                let g = r(gamma);
                let e = (-g * (j - r(1.0))).exp();
                (p_bar * (e - r(1.0)) / g, -p_bar * k * e)
            }
        }
    }

    /// Adjoint of the stress at rest of a fluid, `-p(k, j) I`: adds the adjoints of `k` and `j`
    /// for the stress's adjoint `stress_bar` to `k_bar` and `j_bar`.
    #[inline]
    pub fn add_rest_stress_adjoint(&self, k: Real, j: Real, stress_bar: &M3, k_bar: &mut Real, j_bar: &mut Real) {
        let (kb, jb) = self.pressure_adjoint(k, j, -(stress_bar.x_axis.x + stress_bar.y_axis.y + stress_bar.z_axis.z));
        *k_bar += kb;
        *j_bar += jb;
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

impl Eos {
    /// Rejects parameter values that make the pressure meaningless; `key` is the table path used
    /// in the message (e.g. "material.eos").
    pub fn validate(&self, key: &str) -> Result<(), MaterialError> {
        match *self {
            Eos::Linear => Ok(()),
            Eos::Tait { gamma } => {
                if gamma.is_finite() && gamma > 0.0 {
                    Ok(())
                } else {
                    Err(MaterialError::out_of_range(format!("{key}.gamma"), "> 0", gamma))
                }
            }
        }
    }
}

/// Shear modulus from `shear_modulus` (G) or, failing that, `poisson_ratio` (nu) with the
/// reference bulk modulus K: G = 3 K (1 - 2 nu) / (2 (1 + nu)) (paper 001 eq. 18). NaN when
/// neither is given; [`resolve_shear_modulus`] is the validating form.
#[inline]
pub fn shear_modulus_of(
    bulk_modulus: f64,
    shear_modulus: Option<f64>,
    poisson_ratio: Option<f64>,
) -> f64 {
    match (shear_modulus, poisson_ratio) {
        (Some(g), _) => g,
        (None, Some(nu)) => 3.0 * bulk_modulus * (1.0 - 2.0 * nu) / (2.0 * (1.0 + nu)),
        (None, None) => f64::NAN,
    }
}

/// Partial derivatives (dG/dK, dG/dnu) of [`shear_modulus_of`]'s G = 3 K (1 - 2 nu) / (2 (1 + nu)),
/// for the adjoints of the materials that take `poisson_ratio`.
#[inline]
pub fn shear_modulus_of_partials(bulk_modulus: f64, nu: f64) -> (f64, f64) {
    (3.0 * (1.0 - 2.0 * nu) / (2.0 * (1.0 + nu)), -9.0 * bulk_modulus / (2.0 * (1.0 + nu) * (1.0 + nu)))
}

/// Shear modulus of a material whose scenario gives exactly one of `shear_modulus` (G) and
/// `poisson_ratio` (nu); with nu, G = 3 K (1 - 2 nu) / (2 (1 + nu)) from the reference bulk modulus
/// K (paper 001 eq. 18). Errors name the keys under `key` (e.g. "material").
pub fn resolve_shear_modulus(
    key: &str,
    bulk_modulus: f64,
    shear_modulus: Option<f64>,
    poisson_ratio: Option<f64>,
) -> Result<f64, MaterialError> {
    match (shear_modulus, poisson_ratio) {
        (Some(g), None) => {
            if g.is_finite() && g > 0.0 {
                Ok(g)
            } else {
                Err(MaterialError::out_of_range(format!("{key}.shear_modulus"), "> 0", g))
            }
        }
        (None, Some(nu)) => {
            // nu -> 0.5 is the incompressible limit G -> 0, which has no elastic shear response.
            if nu.is_finite() && nu > -1.0 && nu < 0.5 {
                Ok(shear_modulus_of(bulk_modulus, None, Some(nu)))
            } else {
                Err(MaterialError::out_of_range(format!("{key}.poisson_ratio"), "in (-1, 0.5)", nu))
            }
        }
        (Some(_), Some(_)) => Err(MaterialError::BothGiven { table: key.into(), first: "shear_modulus", second: "poisson_ratio" }),
        (None, None) => Err(MaterialError::NeitherGiven { table: key.into(), first: "shear_modulus", second: "poisson_ratio" }),
    }
}
