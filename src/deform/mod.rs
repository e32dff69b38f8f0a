//! TEMPORARY STAND-IN for the lead's `deform` module (server branch only).
//!
//! It mirrors the documented API of /work/notes/deform-api.md so the server
//! compiles and its tests run before the real solver lands; the "solver" just
//! moves handle vertices part of the way to their targets each iteration.
//! Replaced wholesale by `main`'s `src/deform/` at merge time.
#![allow(missing_docs)]

use std::collections::HashMap;
use std::sync::Arc;

use nalgebra::{UnitQuaternion, Vector3};
use parking_lot::Mutex;
use serde::{Deserialize, Serialize};

use crate::mesh::{Mesh, MeshError};

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Energy {
    Membrane,
    ThinPlate,
    Combined { ks: f64, kb: f64 },
    #[default]
    #[serde(rename = "total")]
    TotalCurvature,
    #[serde(rename = "total-paper")]
    TotalCurvaturePaper,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DetailTerm {
    Linear,
    #[default]
    Nonlinear,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    #[default]
    Default,
    Paper,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    pub energy: Energy,
    pub lambda1: f64,
    pub lambda2: f64,
    pub detail: DetailTerm,
    pub mode: Mode,
    pub tol: f64,
    pub max_iters: usize,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            energy: Energy::default(),
            lambda1: 0.0,
            lambda2: 1.0,
            detail: DetailTerm::default(),
            mode: Mode::default(),
            tol: 1e-3,
            max_iters: 100,
        }
    }
}

impl Params {
    pub fn validate(&self) -> Result<(), DeformError> {
        if !(self.tol > 0.0) || !self.lambda1.is_finite() || self.lambda1 < 0.0 {
            return Err(DeformError::InvalidParams {
                reason: "tol must be > 0, lambda1 >= 0".into(),
            });
        }
        Ok(())
    }
}

#[derive(Debug, thiserror::Error)]
pub enum DeformError {
    #[error("invalid parameters: {reason}")]
    InvalidParams { reason: String },
    #[error("vertex {vertex} out of range (mesh has {count} vertices)")]
    UnknownVertex { vertex: u32, count: usize },
    #[error("handle `{name}` selects no vertex")]
    EmptyHandle { name: String },
    #[error("vertex {vertex} is in two sets")]
    OverlappingSets { vertex: u32 },
    #[error("no constraints")]
    NoConstraints,
    #[error("non-finite value in {what}")]
    NonFinite { what: String },
    #[error(transparent)]
    Mesh(#[from] MeshError),
}

#[derive(Debug, Clone, PartialEq)]
pub struct RigidTransform {
    pub rotation: UnitQuaternion<f64>,
    pub translation: [f64; 3],
    pub pivot: [f64; 3],
}

impl RigidTransform {
    pub fn identity(pivot: [f64; 3]) -> Self {
        RigidTransform { rotation: UnitQuaternion::identity(), translation: [0.0; 3], pivot }
    }
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let v = Vector3::new(p[0] - self.pivot[0], p[1] - self.pivot[1], p[2] - self.pivot[2]);
        let r = self.rotation * v;
        [
            self.pivot[0] + r.x + self.translation[0],
            self.pivot[1] + r.y + self.translation[1],
            self.pivot[2] + r.z + self.translation[2],
        ]
    }
    pub fn then(&self, d_rotation: UnitQuaternion<f64>, d_translation: [f64; 3]) -> Self {
        RigidTransform {
            rotation: d_rotation * self.rotation,
            translation: [
                self.translation[0] + d_translation[0],
                self.translation[1] + d_translation[1],
                self.translation[2] + d_translation[2],
            ],
            pivot: self.pivot,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
pub enum VertexSet {
    List(Vec<u32>),
    Box { r#box: BoxSel },
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BoxSel {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RotateSpec {
    pub axis: [f64; 3],
    pub degrees: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandleSpec {
    pub name: String,
    pub vertices: VertexSet,
    #[serde(default)]
    pub translate: Option<[f64; 3]>,
    #[serde(default)]
    pub rotate: Option<RotateSpec>,
    #[serde(default)]
    pub pivot: Option<[f64; 3]>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintsSpec {
    #[serde(default)]
    pub fixed: Option<VertexSet>,
    #[serde(default)]
    pub handles: Vec<HandleSpec>,
}

fn resolve_set(set: &VertexSet, mesh: &Mesh) -> Result<Vec<u32>, DeformError> {
    let n = mesh.num_vertices();
    let mut v = match set {
        VertexSet::List(l) => {
            for &i in l {
                if i as usize >= n {
                    return Err(DeformError::UnknownVertex { vertex: i, count: n });
                }
            }
            l.clone()
        }
        VertexSet::Box { r#box } => (0..n as u32)
            .filter(|&i| {
                let p = mesh.positions()[i as usize];
                (0..3).all(|k| p[k] >= r#box.min[k] && p[k] <= r#box.max[k])
            })
            .collect(),
    };
    v.sort_unstable();
    v.dedup();
    Ok(v)
}

impl ConstraintsSpec {
    pub fn resolve(&self, mesh: &Mesh) -> Result<Constraints, DeformError> {
        let fixed = match &self.fixed {
            Some(s) => resolve_set(s, mesh)?,
            None => vec![],
        };
        let mut handles = Vec::new();
        for h in &self.handles {
            let vertices = resolve_set(&h.vertices, mesh)?;
            if vertices.is_empty() {
                return Err(DeformError::EmptyHandle { name: h.name.clone() });
            }
            if let Some(&v) = vertices.iter().find(|v| fixed.binary_search(v).is_ok()) {
                return Err(DeformError::OverlappingSets { vertex: v });
            }
            let mut c = [0.0; 3];
            for &i in &vertices {
                let p = mesh.positions()[i as usize];
                for k in 0..3 {
                    c[k] += p[k] / vertices.len() as f64;
                }
            }
            let mut target = RigidTransform::identity(h.pivot.unwrap_or(c));
            let rot = match &h.rotate {
                Some(r) => UnitQuaternion::from_axis_angle(
                    &nalgebra::Unit::new_normalize(Vector3::from(r.axis)),
                    r.degrees.to_radians(),
                ),
                None => UnitQuaternion::identity(),
            };
            target = target.then(rot, h.translate.unwrap_or([0.0; 3]));
            handles.push(HandleGroup { name: h.name.clone(), vertices, rest_centroid: c, target });
        }
        if fixed.is_empty() && handles.is_empty() {
            return Err(DeformError::NoConstraints);
        }
        Ok(Constraints { fixed, handles })
    }
}

#[derive(Debug, Clone)]
pub struct Constraints {
    pub fixed: Vec<u32>,
    pub handles: Vec<HandleGroup>,
}

#[derive(Debug, Clone)]
pub struct HandleGroup {
    pub name: String,
    pub vertices: Vec<u32>,
    pub rest_centroid: [f64; 3],
    pub target: RigidTransform,
}

pub struct Rest {
    mesh: Mesh,
}
impl Rest {
    pub fn new(mesh: Mesh) -> Result<Rest, DeformError> {
        Ok(Rest { mesh })
    }
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }
}

pub struct Factor {
    bytes: usize,
}
impl Factor {
    pub fn build(rest: &Rest, _p: &Params, c: &Constraints) -> Result<Factor, DeformError> {
        std::thread::sleep(std::time::Duration::from_millis(20));
        Ok(Factor { bytes: rest.mesh.num_vertices() * 64 + c.fixed.len() })
    }
    pub fn memory_bytes(&self) -> usize {
        self.bytes
    }
}

#[derive(Hash, Eq, PartialEq, Clone)]
pub struct FactorKey(String);
impl FactorKey {
    pub fn new(p: &Params, c: &Constraints) -> Self {
        let hv: Vec<&Vec<u32>> = c.handles.iter().map(|h| &h.vertices).collect();
        FactorKey(format!("{:?}{:?}{:?}", p, c.fixed, hv))
    }
}

pub struct FactorCache {
    inner: Mutex<(HashMap<FactorKey, Arc<Factor>>, u64, u64)>,
}
impl FactorCache {
    pub fn new(_budget_bytes: usize) -> Self {
        FactorCache { inner: Mutex::new((HashMap::new(), 0, 0)) }
    }
    pub fn get_or_build(&self, rest: &Rest, p: &Params, c: &Constraints) -> Result<Arc<Factor>, DeformError> {
        let key = FactorKey(format!("{:p}{:?}", rest, FactorKey::new(p, c).0));
        if let Some(f) = self.inner.lock().0.get(&key).cloned() {
            self.inner.lock().2 += 1;
            return Ok(f);
        }
        let f = Arc::new(Factor::build(rest, p, c)?);
        let mut g = self.inner.lock();
        g.1 += 1;
        g.0.insert(key, f.clone());
        Ok(f)
    }
    pub fn builds(&self) -> u64 {
        self.inner.lock().1
    }
    pub fn hits(&self) -> u64 {
        self.inner.lock().2
    }
    pub fn bytes(&self) -> usize {
        self.inner.lock().0.values().map(|f| f.bytes).sum()
    }
    pub fn len(&self) -> usize {
        self.inner.lock().0.len()
    }
}

pub struct Deformer {
    rest: Arc<Rest>,
    _params: Params,
    pose: Vec<[f64; 3]>,
}

#[derive(Debug, Clone)]
pub struct StepReport {
    pub iterations: usize,
    pub last_update: f64,
    pub converged: bool,
    pub diverged: bool,
}

impl Deformer {
    pub fn new(rest: Arc<Rest>, params: Params) -> Self {
        let pose = rest.mesh.positions().to_vec();
        Deformer { rest, _params: params, pose }
    }
    pub fn pose(&self) -> &[[f64; 3]] {
        &self.pose
    }
    pub fn set_pose(&mut self, pose: Vec<[f64; 3]>) -> Result<(), DeformError> {
        if pose.len() != self.pose.len() {
            return Err(DeformError::InvalidParams { reason: "pose length".into() });
        }
        self.pose = pose;
        Ok(())
    }
    pub fn reset(&mut self) {
        self.pose = self.rest.mesh.positions().to_vec();
    }
    pub fn step(&mut self, _f: &Factor, c: &Constraints, max_iters: usize) -> Result<StepReport, DeformError> {
        let rest = self.rest.mesh.positions();
        let mut it = 0;
        let mut upd = 0.0;
        while it < max_iters {
            it += 1;
            upd = 0.0f64;
            for h in &c.handles {
                for &v in &h.vertices {
                    let t = h.target.apply(rest[v as usize]);
                    let p = &mut self.pose[v as usize];
                    for k in 0..3 {
                        let d = 0.5 * (t[k] - p[k]);
                        p[k] += d;
                        upd = upd.max(d.abs());
                    }
                }
            }
            if upd < 1e-9 {
                break;
            }
        }
        Ok(StepReport { iterations: it, last_update: upd, converged: upd < 1e-9, diverged: false })
    }
}
