//! Masses and inertias of the printed parts, from their shapes and PLA's density.
//!
//! The repository draws each part as the boxes and cylinders of `urdf/eezybot.urdf` (it
//! carries no meshes of the printed parts). A printed part is not solid: two perimeters
//! and 20 % infill fill about half of the thin EezyBot parts' envelope, so a part's mass
//! is `PLA_DENSITY · PRINT_FILL · volume`. The servos, which are not printed, are added
//! at their datasheet masses where they ride (docs/twin.md has the table).

use nalgebra::{Matrix3, Vector3};

/// PLA's density (kg/m³): 1.24 g/cm³, as filament makers give it (NatureWorks Ingeo).
pub const PLA_DENSITY: f64 = 1240.0;

/// The part of a printed part's envelope that is plastic: 2 perimeters and 20 % infill
/// in 5–20 mm thick parts (our estimate, docs/twin.md).
pub const PRINT_FILL: f64 = 0.5;

/// A solid shape at an offset (its own axes parallel to its body's).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// Full side lengths (m).
    Box([f64; 3]),
    /// Radius and length (m), along z.
    Cylinder {
        /// Radius (m).
        radius: f64,
        /// Length (m).
        length: f64,
    },
}

impl Shape {
    /// Volume (m³).
    pub fn volume(&self) -> f64 {
        match *self {
            Shape::Box([x, y, z]) => x * y * z,
            Shape::Cylinder { radius, length } => std::f64::consts::PI * radius * radius * length,
        }
    }

    /// Principal moments about its centre (kg·m²) for a mass.
    fn inertia(&self, mass: f64) -> Vector3<f64> {
        match *self {
            Shape::Box([x, y, z]) => {
                Vector3::new(y * y + z * z, x * x + z * z, x * x + y * y) * (mass / 12.0)
            }
            Shape::Cylinder {
                radius: r,
                length: h,
            } => {
                let side = mass * (3.0 * r * r + h * h) / 12.0;
                Vector3::new(side, side, mass * r * r / 2.0)
            }
        }
    }
}

/// A body's mass properties: mass, centre of mass and inertia about it (body axes).
#[derive(Clone, Debug, PartialEq)]
pub struct MassProperties {
    /// kg.
    pub mass: f64,
    /// Centre of mass in the body frame (m).
    pub com: Vector3<f64>,
    /// Inertia tensor about the centre of mass, body axes (kg·m²).
    pub inertia: Matrix3<f64>,
}

impl MassProperties {
    /// The combined properties of shapes at offsets, each of mass `density · volume`,
    /// plus point-like extras `(mass, position)` (servos: their own inertia about their
    /// centre is left out, the offset's dominates). `None` when the total mass is zero.
    pub fn of(
        shapes: &[(Shape, Vector3<f64>)],
        density: f64,
        extras: &[(f64, Vector3<f64>)],
    ) -> Option<MassProperties> {
        let mut parts: Vec<(f64, Vector3<f64>, Matrix3<f64>)> = shapes
            .iter()
            .map(|(shape, at)| {
                let m = density * shape.volume();
                (m, *at, Matrix3::from_diagonal(&shape.inertia(m)))
            })
            .collect();
        parts.extend(extras.iter().map(|(m, at)| (*m, *at, Matrix3::zeros())));
        let mass: f64 = parts.iter().map(|p| p.0).sum();
        if mass <= 0.0 {
            return None;
        }
        let com = parts.iter().map(|(m, at, _)| at * *m).sum::<Vector3<f64>>() / mass;
        // parallel axis: I + m (|d|² E − d dᵀ)
        let inertia = parts
            .iter()
            .map(|(m, at, i)| {
                let d = at - com;
                i + (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * *m
            })
            .sum();
        Some(MassProperties { mass, com, inertia })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_cubes_side_by_side_are_a_box() {
        let c = Shape::Box([0.01, 0.01, 0.01]);
        let two = MassProperties::of(
            &[
                (c, Vector3::new(-0.005, 0.0, 0.0)),
                (c, Vector3::new(0.005, 0.0, 0.0)),
            ],
            1000.0,
            &[],
        )
        .unwrap();
        let one = MassProperties::of(
            &[(Shape::Box([0.02, 0.01, 0.01]), Vector3::zeros())],
            1000.0,
            &[],
        )
        .unwrap();
        assert!((two.mass - one.mass).abs() < 1e-15);
        assert!((two.com - one.com).norm() < 1e-15);
        assert!((two.inertia - one.inertia).norm() < 1e-15);
    }

    #[test]
    fn a_point_mass_adds_its_offset_inertia() {
        let p = MassProperties::of(
            &[],
            0.0,
            &[
                (0.1, Vector3::new(0.0, 0.0, 0.1)),
                (0.1, Vector3::new(0.0, 0.0, -0.1)),
            ],
        )
        .unwrap();
        assert!((p.inertia[(0, 0)] - 0.002).abs() < 1e-15);
        assert_eq!(p.inertia[(2, 2)], 0.0);
        assert!(MassProperties::of(&[], 1000.0, &[]).is_none());
    }

    #[test]
    fn a_cylinder_spins_about_z_with_half_mr2() {
        let s = Shape::Cylinder {
            radius: 0.1,
            length: 0.2,
        };
        let p = MassProperties::of(&[(s, Vector3::zeros())], 1.0 / s.volume(), &[]).unwrap();
        assert!((p.inertia[(2, 2)] - 0.005).abs() < 1e-12);
    }
}
