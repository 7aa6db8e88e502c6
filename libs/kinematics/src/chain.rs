//! A serial chain between two links of a URDF tree, as the numerical IK sees it.
//!
//! The chain's *variables* are the joints a solver may move (the actuated ones). Every
//! movable joint along the chain has a position that is an affine function of the
//! variables ([`JointMap`]): a variable itself, a URDF `mimic` joint (multiplier times
//! leader, plus offset), or a *passive* joint declared with [`ChainBuilder::passive`] (any linear
//! combination, e.g. the EezyBot's `wrist_joint` = −shoulder − elbow). Passive and mimic
//! joints off the chain can be declared too, so [`SerialChain::joint_positions`] gives
//! every joint position a `joint_states` message needs.
//!
//! Limits are a box on the variables (from the URDF, or [`ChainBuilder::limits`]) plus
//! linear inequalities `lower ≤ a·x ≤ upper` ([`LinearConstraint`]): those declared with
//! [`ChainBuilder::constraint`] (e.g. the EezyBot's φ = shoulder + elbow within −65°…20°)
//! and, by default, the URDF limits of every dependent joint.
//!
//! # Examples
//! ```
//! use eezybot_kinematics::chain::SerialChain;
//! use eezybot_kinematics::urdf::RobotModel;
//! let m = RobotModel::from_urdf_str(r#"<robot name="r">
//!   <link name="a"/><link name="b"/><link name="c"/>
//!   <joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
//!     <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
//!   <joint name="t" type="fixed"><parent link="b"/><child link="c"/><origin xyz="0.5 0 0"/></joint>
//! </robot>"#, "inline").unwrap();
//! let chain = SerialChain::from_model(&m, "a", "c").unwrap();
//! assert_eq!(chain.dof(), 1);
//! let tip = chain.forward(&[std::f64::consts::FRAC_PI_2]).unwrap();
//! assert!((tip.translation.vector - nalgebra::Vector3::new(0.0, 0.5, 0.0)).norm() < 1e-15);
//! ```

use crate::rng::SplitMix64;
use crate::urdf::{JointKind, RobotModel};
use crate::KinematicsError;
use nalgebra::{Isometry3, Matrix6xX, Translation3, Unit, UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::f64::consts::PI;

/// How a chain joint moves its child frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Motion {
    /// Rotation (rad) about the unit axis, in the joint frame.
    Revolute(Unit<Vector3<f64>>),
    /// Translation (m) along the unit axis, in the joint frame.
    Prismatic(Unit<Vector3<f64>>),
}

impl Motion {
    /// The child frame in the joint frame at position `q`.
    pub fn transform(&self, q: f64) -> Isometry3<f64> {
        match self {
            Motion::Revolute(axis) => Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(axis, q),
            ),
            Motion::Prismatic(axis) => Isometry3::from_parts(
                Translation3::from(axis.into_inner() * q),
                UnitQuaternion::identity(),
            ),
        }
    }
}

/// A joint position as an affine function of the chain variables:
/// `Σ coefficient · x[variable] + offset`.
#[derive(Clone, Debug, PartialEq)]
pub struct JointMap {
    /// `(variable index, coefficient)` pairs.
    pub terms: Vec<(usize, f64)>,
    /// Constant offset (rad or m).
    pub offset: f64,
}

impl JointMap {
    /// The joint position for variables `x` (which must be long enough).
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::chain::JointMap;
    /// let wrist = JointMap { terms: vec![(1, -1.0), (2, -1.0)], offset: 0.0 };
    /// assert_eq!(wrist.value(&[0.0, 1.5, -1.5]), 0.0);
    /// ```
    pub fn value(&self, x: &[f64]) -> f64 {
        self.terms.iter().fold(self.offset, |acc, (i, c)| {
            acc + c * x.get(*i).copied().unwrap_or(0.0)
        })
    }

    /// Is it exactly one variable with coefficient 1 and no offset?
    pub fn is_variable(&self) -> Option<usize> {
        match self.terms.as_slice() {
            [(i, c)] if *c == 1.0 && self.offset == 0.0 => Some(*i),
            _ => None,
        }
    }
}

/// One movable joint along the chain.
#[derive(Clone, Debug, PartialEq)]
pub struct ChainJoint {
    /// URDF joint name.
    pub name: String,
    /// Pose of the joint frame in the previous chain joint's child frame (or the base
    /// link), fixed joints in between folded in.
    pub origin: Isometry3<f64>,
    /// How it moves.
    pub motion: Motion,
    /// Its position as a function of the variables.
    pub map: JointMap,
}

/// A joint the solver may move.
#[derive(Clone, Debug, PartialEq)]
pub struct ChainVariable {
    /// URDF joint name.
    pub name: String,
    /// Lower bound (rad or m; −∞ for a continuous joint).
    pub lower: f64,
    /// Upper bound (rad or m; +∞ for a continuous joint).
    pub upper: f64,
    /// Rotates without limits (URDF `continuous`).
    pub continuous: bool,
}

/// A linear inequality on the variables: `lower ≤ coefficients · x ≤ upper`.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearConstraint {
    /// What it limits (a joint name or the name given to [`ChainBuilder::constraint`]).
    pub name: String,
    /// One coefficient per variable.
    pub coefficients: Vec<f64>,
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
}

impl LinearConstraint {
    /// `coefficients · x`.
    pub fn value(&self, x: &[f64]) -> f64 {
        self.coefficients.iter().zip(x).map(|(a, b)| a * b).sum()
    }
}

/// Which limit a [`LimitProximity`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LimitId {
    /// The bounds of variable `i`.
    Variable(usize),
    /// Linear constraint `i` of [`SerialChain::constraints`].
    Constraint(usize),
}

/// Which bound.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Bound {
    /// The lower one.
    Lower,
    /// The upper one.
    Upper,
}

/// A configuration at or near one of the chain's limits.
#[derive(Clone, Debug, PartialEq)]
pub struct LimitProximity {
    /// Which limit.
    pub limit: LimitId,
    /// Which side.
    pub bound: Bound,
    /// How far inside (≥ 0) or outside (< 0) the limit the configuration is (rad or m,
    /// along the constraint's unit normal for a linear constraint).
    pub distance: f64,
    /// Unit direction in variable space that moves away from the limit.
    pub away: Vec<f64>,
}

/// Builds a [`SerialChain`] from a [`RobotModel`]: passive joints, limit overrides and
/// linear constraints.
///
/// # Examples
/// The EezyBot's chain (what [`crate::Arm::serial_chain`] builds):
/// ```
/// use eezybot_kinematics::chain::ChainBuilder;
/// use eezybot_kinematics::urdf::RobotModel;
/// let model = RobotModel::load(std::path::Path::new(concat!(
///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/eezybot.urdf"))).unwrap();
/// let chain = ChainBuilder::new(&model, "base_link", "tool0")
///     .passive("wrist_joint", &[("shoulder_joint", -1.0), ("elbow_joint", -1.0)], 0.0)
///     .constraint("forearm_elevation", &[("shoulder_joint", 1.0), ("elbow_joint", 1.0)],
///                 (-65f64).to_radians(), 20f64.to_radians())
///     .build()
///     .unwrap();
/// let names: Vec<&str> = chain.variables().iter().map(|v| v.name.as_str()).collect();
/// assert_eq!(names, ["base_joint", "shoulder_joint", "elbow_joint"]);
/// ```
#[derive(Clone, Debug)]
pub struct ChainBuilder<'a> {
    model: &'a RobotModel,
    base: String,
    tip: String,
    passive: Vec<(String, Terms, f64)>,
    limits: Vec<(String, f64, f64)>,
    constraints: Vec<(String, Terms, f64, f64)>,
    dependent_limits: bool,
}

/// `(joint name, coefficient)` pairs.
type Terms = Vec<(String, f64)>;

/// Joint position in terms of variable names while building.
type NamedMap = (Terms, f64);

impl<'a> ChainBuilder<'a> {
    /// A chain from link `base` to link `tip` of `model`.
    pub fn new(model: &'a RobotModel, base: &str, tip: &str) -> Self {
        ChainBuilder {
            model,
            base: base.to_string(),
            tip: tip.to_string(),
            passive: Vec::new(),
            limits: Vec::new(),
            constraints: Vec::new(),
            dependent_limits: true,
        }
    }

    /// Declares `joint` passive: its position is `Σ coefficient · position(term) + offset`,
    /// where each term names a joint of the model (a variable, or another passive or mimic
    /// joint). It may be on the chain or off it (then it is only reported by
    /// [`SerialChain::joint_positions`]).
    pub fn passive(mut self, joint: &str, terms: &[(&str, f64)], offset: f64) -> Self {
        self.passive.push((
            joint.to_string(),
            terms.iter().map(|(n, c)| (n.to_string(), *c)).collect(),
            offset,
        ));
        self
    }

    /// Replaces the URDF limits of a variable.
    pub fn limits(mut self, variable: &str, lower: f64, upper: f64) -> Self {
        self.limits.push((variable.to_string(), lower, upper));
        self
    }

    /// Adds `lower ≤ Σ coefficient · position(term) ≤ upper`, terms naming joints of the
    /// model as in [`ChainBuilder::passive`].
    pub fn constraint(mut self, name: &str, terms: &[(&str, f64)], lower: f64, upper: f64) -> Self {
        self.constraints.push((
            name.to_string(),
            terms.iter().map(|(n, c)| (n.to_string(), *c)).collect(),
            lower,
            upper,
        ));
        self
    }

    /// Whether the URDF limits of dependent (mimic, passive) joints become linear
    /// constraints on the variables (default: yes).
    pub fn dependent_joint_limits(mut self, enabled: bool) -> Self {
        self.dependent_limits = enabled;
        self
    }

    /// Checks everything and builds the chain.
    pub fn build(self) -> Result<SerialChain, KinematicsError> {
        let model = self.model;
        for link in [&self.base, &self.tip] {
            if !model.links.contains(link) {
                return Err(KinematicsError::UnknownLink { link: link.clone() });
            }
        }
        // Walk from the tip up to the base.
        let parent_joint: HashMap<&str, usize> = model
            .joints
            .iter()
            .enumerate()
            .map(|(i, j)| (j.child.as_str(), i))
            .collect();
        let mut path = Vec::new();
        let mut link = self.tip.as_str();
        while link != self.base {
            let Some(&j) = parent_joint.get(link) else {
                return Err(KinematicsError::NotAChain {
                    base: self.base.clone(),
                    tip: self.tip.clone(),
                });
            };
            path.push(j);
            link = model.joints[j].parent.as_str();
        }
        path.reverse();

        let passive: HashMap<String, NamedMap> = self
            .passive
            .iter()
            .map(|(n, t, o)| (n.clone(), (t.clone(), *o)))
            .collect();
        for name in passive.keys() {
            match model.joint(name) {
                None => {
                    return Err(KinematicsError::BadChainJoint {
                        joint: name.clone(),
                        why: "declared passive but not in the robot model",
                    })
                }
                Some(j) if !j.is_movable() => {
                    return Err(KinematicsError::BadChainJoint {
                        joint: name.clone(),
                        why: "declared passive but it does not move",
                    })
                }
                Some(_) => {}
            }
        }
        let is_dependent = |name: &str| {
            passive.contains_key(name) || model.joint(name).is_some_and(|j| j.mimic.is_some())
        };

        // Variables: the independent movable joints of the chain, base to tip.
        let mut variables: Vec<ChainVariable> = Vec::new();
        for &j in &path {
            let jm = &model.joints[j];
            if jm.is_movable() && !is_dependent(&jm.name) {
                variables.push(variable_of(jm));
            }
        }
        let resolver = Resolver {
            model,
            passive: &passive,
        };
        // On-chain joints (may add variables: a leader off the chain still moves the tip).
        let mut joints = Vec::new();
        let mut pending = Isometry3::identity();
        for &j in &path {
            let jm = &model.joints[j];
            let motion = match &jm.kind {
                JointKind::Revolute { axis, .. } | JointKind::Continuous { axis } => {
                    Motion::Revolute(*axis)
                }
                JointKind::Prismatic { axis, .. } => Motion::Prismatic(*axis),
                JointKind::Fixed | JointKind::Unsupported => {
                    pending *= jm.origin;
                    continue;
                }
            };
            let named = resolver.resolve(&jm.name, 0)?;
            let map = to_index_map(&named, &mut variables, model, true)?;
            joints.push(ChainJoint {
                name: jm.name.clone(),
                origin: pending * jm.origin,
                motion,
                map,
            });
            pending = Isometry3::identity();
        }
        let tip_offset = pending;

        // Overridden limits.
        for (name, lower, upper) in &self.limits {
            if lower.is_nan() || upper.is_nan() || lower > upper {
                return Err(KinematicsError::InvalidLimits {
                    name: name.clone(),
                    lower: *lower,
                    upper: *upper,
                });
            }
            let v = variables
                .iter_mut()
                .find(|v| &v.name == name)
                .ok_or_else(|| KinematicsError::BadChainJoint {
                    joint: name.clone(),
                    why: "limits given for a joint that is not a chain variable",
                })?;
            v.lower = *lower;
            v.upper = *upper;
            v.continuous = false;
        }

        // Off-chain dependent joints whose positions follow from the variables.
        let on_chain: Vec<&str> = joints.iter().map(|j| j.name.as_str()).collect();
        let mut others = Vec::new();
        for jm in &model.joints {
            if on_chain.contains(&jm.name.as_str()) || !jm.is_movable() {
                continue;
            }
            let explicit = passive.contains_key(&jm.name);
            if !explicit && jm.mimic.is_none() {
                continue;
            }
            let resolved = resolver
                .resolve(&jm.name, 0)
                .and_then(|named| to_index_map(&named, &mut variables, model, false));
            match resolved {
                Ok(map) => others.push((jm.name.clone(), map)),
                Err(e) if explicit => return Err(e),
                Err(_) => {} // a mimic of something that is not a chain variable (the claw)
            }
        }

        // Constraints: explicit ones, then the limits of dependent joints.
        let n = variables.len();
        let mut constraints = Vec::new();
        for (name, terms, lower, upper) in &self.constraints {
            if lower.is_nan() || upper.is_nan() || lower > upper {
                return Err(KinematicsError::InvalidLimits {
                    name: name.clone(),
                    lower: *lower,
                    upper: *upper,
                });
            }
            let mut sum: NamedMap = (Vec::new(), 0.0);
            for (joint, c) in terms {
                let (t, o) = resolver.resolve(joint, 0)?;
                sum.0.extend(t.into_iter().map(|(v, k)| (v, k * c)));
                sum.1 += c * o;
            }
            let map = to_index_map(&sum, &mut variables, model, false)?;
            constraints.push(affine_constraint(name, &map, n, *lower, *upper));
        }
        if self.dependent_limits {
            let dependents = joints
                .iter()
                .map(|j| (j.name.as_str(), &j.map))
                .chain(others.iter().map(|(n, m)| (n.as_str(), m)));
            for (name, map) in dependents {
                if map.is_variable().is_some() {
                    continue;
                }
                let limits = match model.joint(name).map(|j| &j.kind) {
                    Some(
                        JointKind::Revolute { limits, .. } | JointKind::Prismatic { limits, .. },
                    ) => *limits,
                    _ => continue,
                };
                constraints.push(affine_constraint(name, map, n, limits.0, limits.1));
            }
        }
        Ok(SerialChain {
            base: self.base,
            tip: self.tip,
            joints,
            tip_offset,
            variables,
            constraints,
            others,
        })
    }
}

fn variable_of(jm: &crate::urdf::JointModel) -> ChainVariable {
    let (lower, upper, continuous) = match &jm.kind {
        JointKind::Revolute { limits, .. } | JointKind::Prismatic { limits, .. } => {
            (limits.0, limits.1, false)
        }
        _ => (f64::NEG_INFINITY, f64::INFINITY, true),
    };
    ChainVariable {
        name: jm.name.clone(),
        lower,
        upper,
        continuous,
    }
}

fn affine_constraint(
    name: &str,
    map: &JointMap,
    n: usize,
    lower: f64,
    upper: f64,
) -> LinearConstraint {
    let mut coefficients = vec![0.0; n];
    for (i, c) in &map.terms {
        coefficients[*i] += c;
    }
    LinearConstraint {
        name: name.to_string(),
        coefficients,
        lower: lower - map.offset,
        upper: upper - map.offset,
    }
}

struct Resolver<'m> {
    model: &'m RobotModel,
    passive: &'m HashMap<String, NamedMap>,
}

impl Resolver<'_> {
    /// A joint's position in terms of independent joint names.
    fn resolve(&self, name: &str, depth: usize) -> Result<NamedMap, KinematicsError> {
        let bad = |why| KinematicsError::BadChainJoint {
            joint: name.to_string(),
            why,
        };
        if depth > 16 {
            return Err(bad("passive/mimic definitions form a loop"));
        }
        let jm = self
            .model
            .joint(name)
            .ok_or_else(|| bad("not in the robot model"))?;
        if !jm.is_movable() {
            return Err(bad("does not move"));
        }
        let expand = |terms: &[(String, f64)], offset: f64| -> Result<NamedMap, KinematicsError> {
            let mut out: NamedMap = (Vec::new(), offset);
            for (leader, c) in terms {
                let (t, o) = self.resolve(leader, depth + 1)?;
                out.0.extend(t.into_iter().map(|(v, k)| (v, k * c)));
                out.1 += c * o;
            }
            Ok(out)
        };
        if let Some((terms, offset)) = self.passive.get(name) {
            return expand(terms, *offset);
        }
        if let Some(m) = &jm.mimic {
            let leader = &self.model.joints[m.leader].name;
            return expand(&[(leader.clone(), m.multiplier)], m.offset);
        }
        Ok((vec![(name.to_string(), 1.0)], 0.0))
    }
}

fn to_index_map(
    named: &NamedMap,
    variables: &mut Vec<ChainVariable>,
    model: &RobotModel,
    may_add: bool,
) -> Result<JointMap, KinematicsError> {
    let mut terms: Vec<(usize, f64)> = Vec::new();
    for (name, c) in &named.0 {
        let i = match variables.iter().position(|v| &v.name == name) {
            Some(i) => i,
            None if may_add => {
                let jm = model
                    .joint(name)
                    .ok_or_else(|| KinematicsError::BadChainJoint {
                        joint: name.clone(),
                        why: "not in the robot model",
                    })?;
                variables.push(variable_of(jm));
                variables.len() - 1
            }
            None => {
                return Err(KinematicsError::BadChainJoint {
                    joint: name.clone(),
                    why: "follows a joint that is not a chain variable",
                })
            }
        };
        match terms.iter_mut().find(|(j, _)| *j == i) {
            Some((_, k)) => *k += c,
            None => terms.push((i, *c)),
        }
    }
    terms.retain(|(_, c)| *c != 0.0);
    Ok(JointMap {
        terms,
        offset: named.1,
    })
}

/// A serial chain from a base link to a tip link, with its variables, limits and the
/// map from variables to every dependent joint. Build it with [`ChainBuilder`] or
/// [`SerialChain::from_model`]. All methods are pure.
#[derive(Clone, Debug, PartialEq)]
pub struct SerialChain {
    base: String,
    tip: String,
    joints: Vec<ChainJoint>,
    tip_offset: Isometry3<f64>,
    variables: Vec<ChainVariable>,
    constraints: Vec<LinearConstraint>,
    others: Vec<(String, JointMap)>,
}

impl SerialChain {
    /// The chain from `base` to `tip` with URDF joints, mimic joints and limits only.
    pub fn from_model(model: &RobotModel, base: &str, tip: &str) -> Result<Self, KinematicsError> {
        ChainBuilder::new(model, base, tip).build()
    }

    /// Base link name.
    pub fn base_link(&self) -> &str {
        &self.base
    }

    /// Tip link name.
    pub fn tip_link(&self) -> &str {
        &self.tip
    }

    /// Number of variables.
    pub fn dof(&self) -> usize {
        self.variables.len()
    }

    /// The variables, in the order of every joint vector `x`.
    pub fn variables(&self) -> &[ChainVariable] {
        &self.variables
    }

    /// Index of the variable for a joint name.
    pub fn variable_index(&self, name: &str) -> Option<usize> {
        self.variables.iter().position(|v| v.name == name)
    }

    /// The movable joints along the chain, base to tip.
    pub fn joints(&self) -> &[ChainJoint] {
        &self.joints
    }

    /// The linear constraints (explicit ones first, then the dependent joints' limits).
    pub fn constraints(&self) -> &[LinearConstraint] {
        &self.constraints
    }

    /// Name of a limit (the variable's joint or the constraint's name).
    pub fn limit_name(&self, limit: LimitId) -> &str {
        match limit {
            LimitId::Variable(i) => self.variables.get(i).map_or("?", |v| v.name.as_str()),
            LimitId::Constraint(i) => self.constraints.get(i).map_or("?", |c| c.name.as_str()),
        }
    }

    /// Checks that `x` has one finite entry per variable.
    pub fn check(&self, x: &[f64]) -> Result<(), KinematicsError> {
        if x.len() != self.dof() {
            return Err(KinematicsError::DimensionMismatch {
                what: "joint vector",
                expected: self.dof(),
                got: x.len(),
            });
        }
        if let Some((index, value)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(KinematicsError::NonFiniteValue {
                what: "joint vector",
                index,
                value: *value,
            });
        }
        Ok(())
    }

    /// Position of every joint that follows from the variables: the chain's joints,
    /// then dependent joints off the chain (URDF order), by URDF name.
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{Arm, urdf::RobotModel};
    /// let model = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/eezybot.urdf"))).unwrap();
    /// let chain = Arm::default().serial_chain(&model).unwrap();
    /// let q = chain.joint_positions(&[0.0, 1.2, -1.5]).unwrap();
    /// let wrist = q.iter().find(|(n, _)| *n == "wrist_joint").unwrap().1;
    /// assert!((wrist - 0.3).abs() < 1e-15); // −φ keeps the plate level
    /// ```
    pub fn joint_positions(&self, x: &[f64]) -> Result<Vec<(&str, f64)>, KinematicsError> {
        self.check(x)?;
        Ok(self
            .joints
            .iter()
            .map(|j| (j.name.as_str(), j.map.value(x)))
            .chain(self.others.iter().map(|(n, m)| (n.as_str(), m.value(x))))
            .collect())
    }

    /// Pose of the tip link in the base link for variables `x`.
    pub fn forward(&self, x: &[f64]) -> Result<Isometry3<f64>, KinematicsError> {
        self.check(x)?;
        Ok(self.forward_unchecked(x))
    }

    pub(crate) fn forward_unchecked(&self, x: &[f64]) -> Isometry3<f64> {
        let mut t = Isometry3::identity();
        for j in &self.joints {
            t = t * j.origin * j.motion.transform(j.map.value(x));
        }
        t * self.tip_offset
    }

    /// Tip pose and geometric Jacobian (6 × dof, in the base frame, about the tip
    /// origin: rows 0–2 the tip's linear velocity, rows 3–5 its angular velocity per unit
    /// rate of each variable; mimic and passive joints included through their maps).
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{Arm, urdf::RobotModel};
    /// let model = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/eezybot.urdf"))).unwrap();
    /// let chain = Arm::default().serial_chain(&model).unwrap();
    /// let (tip, j) = chain.jacobian(&[0.0, 1.5707963267948966, -1.5707963267948966]).unwrap();
    /// // the plate stays level: no angular velocity about y from shoulder or elbow
    /// assert!(j[(4, 1)].abs() < 1e-12 && j[(4, 2)].abs() < 1e-12);
    /// // turning the base moves the tool sideways by its radius
    /// assert!((j[(1, 0)] - tip.translation.vector.x).abs() < 1e-12);
    /// ```
    pub fn jacobian(&self, x: &[f64]) -> Result<(Isometry3<f64>, Matrix6xX<f64>), KinematicsError> {
        self.check(x)?;
        let mut jac = Matrix6xX::zeros(self.dof());
        let tip = self.forward_jacobian_into(x, &mut jac);
        Ok((tip, jac))
    }

    /// FK and Jacobian into a preallocated 6 × dof matrix (no allocation).
    pub(crate) fn forward_jacobian_into(
        &self,
        x: &[f64],
        jac: &mut Matrix6xX<f64>,
    ) -> Isometry3<f64> {
        jac.fill(0.0);
        let mut t = Isometry3::identity();
        for j in &self.joints {
            t *= j.origin;
            let (axis, p) = (t.rotation, t.translation.vector);
            let (lin, ang) = match j.motion {
                // v = w × (p_tip − p) = w × p_tip + (−w × p): the first part is added below
                Motion::Revolute(a) => {
                    let w = axis * a.into_inner();
                    (-w.cross(&p), w)
                }
                Motion::Prismatic(a) => (axis * a.into_inner(), Vector3::zeros()),
            };
            for (i, c) in &j.map.terms {
                let mut col = jac.column_mut(*i);
                for r in 0..3 {
                    col[r] += c * lin[r];
                    col[r + 3] += c * ang[r];
                }
            }
            t *= j.motion.transform(j.map.value(x));
        }
        let tip = t * self.tip_offset;
        let pt = tip.translation.vector;
        for mut col in jac.column_iter_mut() {
            let w = Vector3::new(col[3], col[4], col[5]);
            let add = w.cross(&pt);
            col[0] += add.x;
            col[1] += add.y;
            col[2] += add.z;
        }
        tip
    }

    /// The largest amount by which `x` breaks a limit (0 when inside all of them).
    pub fn limit_violation(&self, x: &[f64]) -> f64 {
        let mut worst: f64 = 0.0;
        for (v, xi) in self.variables.iter().zip(x) {
            worst = worst.max(v.lower - xi).max(xi - v.upper);
        }
        for c in &self.constraints {
            let a = c.value(x);
            worst = worst.max(c.lower - a).max(a - c.upper);
        }
        worst
    }

    /// Is `x` inside every limit, to within `tolerance`?
    pub fn within_limits(&self, x: &[f64], tolerance: f64) -> bool {
        self.limit_violation(x) <= tolerance
    }

    /// Moves `x` into the limits: clamps to the bounds, then projects onto violated
    /// constraints (alternating projections, which end in the feasible set whenever it
    /// is not empty). Returns the violation left (0 when feasible).
    ///
    /// # Examples
    /// ```
    /// use eezybot_kinematics::{Arm, urdf::RobotModel};
    /// let model = RobotModel::load(std::path::Path::new(concat!(
    ///     env!("CARGO_MANIFEST_DIR"), "/../../urdf/eezybot.urdf"))).unwrap();
    /// let chain = Arm::default().serial_chain(&model).unwrap();
    /// // α = 120°, elbow = −60°: φ = 60° is above its 20° limit
    /// let mut x = [0.0, 120f64.to_radians(), -60f64.to_radians()];
    /// assert!(chain.project(&mut x) < 1e-12);
    /// assert!(x[1] + x[2] <= 20f64.to_radians() + 1e-12);
    /// ```
    pub fn project(&self, x: &mut [f64]) -> f64 {
        self.clamp_box(x);
        if self.constraints.is_empty() {
            return 0.0;
        }
        for _ in 0..100 {
            let mut worst: f64 = 0.0;
            for c in &self.constraints {
                let a = c.value(x);
                let excess = if a > c.upper {
                    a - c.upper
                } else if a < c.lower {
                    a - c.lower
                } else {
                    continue;
                };
                worst = worst.max(excess.abs());
                // Only the variables still free to move share the correction.
                let vars = &self.variables;
                let free = |x: &[f64], i: usize, k: f64| {
                    let v = &vars[i];
                    let down = excess * k > 0.0; // x_i must decrease
                    !((down && x[i] <= v.lower) || (!down && x[i] >= v.upper))
                };
                let norm2: f64 = c
                    .coefficients
                    .iter()
                    .enumerate()
                    .filter(|(i, k)| **k != 0.0 && free(x, *i, **k))
                    .map(|(_, k)| k * k)
                    .sum();
                if norm2 == 0.0 {
                    continue;
                }
                let step: Vec<(usize, f64)> = c
                    .coefficients
                    .iter()
                    .enumerate()
                    .filter(|(i, k)| **k != 0.0 && free(x, *i, **k))
                    .map(|(i, k)| (i, excess * k / norm2))
                    .collect();
                for (i, d) in step {
                    x[i] -= d;
                }
                self.clamp_box(x);
            }
            if worst <= 1e-15 {
                break;
            }
        }
        self.limit_violation(x)
    }

    /// Inward normals of the limits that `x` sits on (within `tolerance`) and that the
    /// step `dx` would push through.
    pub(crate) fn blocking_limits(&self, x: &[f64], dx: &[f64], tolerance: f64) -> Vec<Vec<f64>> {
        let n = self.dof();
        let mut out = Vec::new();
        for (i, v) in self.variables.iter().enumerate() {
            if (x[i] <= v.lower + tolerance && dx[i] < 0.0)
                || (x[i] >= v.upper - tolerance && dx[i] > 0.0)
            {
                let mut e = vec![0.0; n];
                e[i] = 1.0;
                out.push(e);
            }
        }
        for c in &self.constraints {
            let (a, d) = (c.value(x), c.value(dx));
            if (a <= c.lower + tolerance && d < 0.0) || (a >= c.upper - tolerance && d > 0.0) {
                out.push(c.coefficients.clone());
            }
        }
        out
    }

    fn clamp_box(&self, x: &mut [f64]) {
        for (xi, v) in x.iter_mut().zip(&self.variables) {
            *xi = xi.clamp(v.lower, v.upper);
        }
    }

    /// Every limit that `x` is within `margin` of (or beyond), with the direction away
    /// from it.
    pub fn near_limits(&self, x: &[f64], margin: f64) -> Vec<LimitProximity> {
        let n = self.dof();
        let mut out = Vec::new();
        for (i, (v, xi)) in self.variables.iter().zip(x).enumerate() {
            for (bound, distance, sign) in [
                (Bound::Lower, xi - v.lower, 1.0),
                (Bound::Upper, v.upper - xi, -1.0),
            ] {
                if distance <= margin {
                    let mut away = vec![0.0; n];
                    away[i] = sign;
                    out.push(LimitProximity {
                        limit: LimitId::Variable(i),
                        bound,
                        distance,
                        away,
                    });
                }
            }
        }
        for (i, c) in self.constraints.iter().enumerate() {
            let norm = c.coefficients.iter().map(|k| k * k).sum::<f64>().sqrt();
            if norm == 0.0 {
                continue;
            }
            let a = c.value(x);
            for (bound, distance, sign) in [
                (Bound::Lower, (a - c.lower) / norm, 1.0),
                (Bound::Upper, (c.upper - a) / norm, -1.0),
            ] {
                if distance <= margin {
                    out.push(LimitProximity {
                        limit: LimitId::Constraint(i),
                        bound,
                        distance,
                        away: c.coefficients.iter().map(|k| sign * k / norm).collect(),
                    });
                }
            }
        }
        out
    }

    /// A random configuration inside the limits: uniform in each variable's bounds
    /// (continuous joints in −π…π, unbounded prismatic ones in −1…1 m), rejection-sampled
    /// against the constraints (projected onto them after 32 misses).
    pub fn random_configuration(&self, rng: &mut SplitMix64) -> Vec<f64> {
        let mut x = vec![0.0; self.dof()];
        self.random_into(rng, &mut x);
        x
    }

    /// [`SerialChain::random_configuration`] into `x` (no allocation).
    pub(crate) fn random_into(&self, rng: &mut SplitMix64, x: &mut [f64]) {
        for _ in 0..32 {
            self.random_box(rng, x);
            if self.within_limits(x, 0.0) {
                return;
            }
        }
        self.project(x);
    }

    fn random_box(&self, rng: &mut SplitMix64, x: &mut [f64]) {
        for (xi, v) in x.iter_mut().zip(&self.variables) {
            let (lo, hi) = match (v.lower.is_finite(), v.upper.is_finite()) {
                (true, true) => (v.lower, v.upper),
                _ if v.continuous
                    || matches!(self.motion_of(&v.name), Some(Motion::Revolute(_))) =>
                {
                    (v.lower.max(-PI), v.upper.min(PI))
                }
                _ => (v.lower.max(-1.0), v.upper.min(1.0)),
            };
            *xi = lo + (hi - lo) * rng.next_f64();
        }
    }

    fn motion_of(&self, name: &str) -> Option<Motion> {
        self.joints
            .iter()
            .find(|j| j.name == name)
            .map(|j| j.motion)
    }
}
