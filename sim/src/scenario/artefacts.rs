//! `[[sphere]]`, `[[plane]]`, `[[cylinder]]`: what stands on the table.

use super::error::{check_finite3, check_range, invalid, ScenarioError};
use crate::artefact::{Cylinder, Plane, Sphere};
use nalgebra::Vector3;
use serde::Deserialize;
use std::path::Path;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSphere {
    center: [f64; 3],
    radius: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawPlane {
    point: [f64; 3],
    normal: [f64; 3],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCylinder {
    point: [f64; 3],
    direction: [f64; 3],
    radius: f64,
}

type Artefacts = (Vec<Sphere>, Vec<Plane>, Vec<Cylinder>);

/// `[[sphere]]`, `[[plane]]`, `[[cylinder]]`.
pub(super) fn build_artefacts(
    sphere: &[RawSphere],
    plane: &[RawPlane],
    cylinder: &[RawCylinder],
    path: &Path,
) -> Result<Artefacts, ScenarioError> {
    let bad = |key: &str, message: String| invalid(path, key, message);
    let vec3 = |v: [f64; 3]| Vector3::new(v[0], v[1], v[2]);
    let mut spheres = Vec::with_capacity(sphere.len());
    for (i, s) in sphere.iter().enumerate() {
        check_finite3(path, &format!("sphere[{i}].center"), s.center)?;
        check_range(
            path,
            &format!("sphere[{i}].radius"),
            s.radius,
            0.0,
            1e4,
            false,
        )?;
        spheres.push(Sphere::new(vec3(s.center), s.radius).expect("validated above"));
    }
    let mut planes = Vec::with_capacity(plane.len());
    for (i, s) in plane.iter().enumerate() {
        check_finite3(path, &format!("plane[{i}].point"), s.point)?;
        check_finite3(path, &format!("plane[{i}].normal"), s.normal)?;
        planes.push(
            Plane::new(vec3(s.point), vec3(s.normal))
                .ok_or_else(|| bad(&format!("plane[{i}].normal"), "must not be zero".into()))?,
        );
    }
    let mut cylinders = Vec::with_capacity(cylinder.len());
    for (i, s) in cylinder.iter().enumerate() {
        check_finite3(path, &format!("cylinder[{i}].point"), s.point)?;
        check_finite3(path, &format!("cylinder[{i}].direction"), s.direction)?;
        check_range(
            path,
            &format!("cylinder[{i}].radius"),
            s.radius,
            0.0,
            1e4,
            false,
        )?;
        cylinders.push(
            Cylinder::new(vec3(s.point), vec3(s.direction), s.radius).ok_or_else(|| {
                bad(
                    &format!("cylinder[{i}].direction"),
                    "must not be zero".into(),
                )
            })?,
        );
    }
    Ok((spheres, planes, cylinders))
}
