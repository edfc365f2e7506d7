//! Where a run starts: a scene's initial condition bound to a molecule (names to indices, the
//! scene's units to atomic units, velocities to momenta, lab-frame positions fitted to q and an
//! orientation) and the system a run integrates. `rovib run`, `rovib bench` and any other
//! runner start here.

use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::runtime::diagnostic::{Compact, FileError, MAX_INPUT_BYTES, ReadError, Source, read_text_capped};
use crate::runtime::frames::{FitOptions, FrameError, LabState, body_of_lab_exact, from_lab_body};
use crate::runtime::hamiltonian::{
    BodyState, PhaseState, ReducedSystem, Reduction, ReductionError, RotationPart, euler_momenta_from_angular_momentum,
    momenta_from_velocities, quaternion_of_euler, w_matrix,
};
use crate::runtime::integrate::OdeSystem;
use crate::runtime::nalgebra::{SMatrix, SVector, Vector3};
use crate::runtime::{KineticMatrices, Molecule};
use crate::scene::{Initial, InitialAngularMomentum, Momenta, Named, Scene, parse_scene};

/// Why a scene cannot start a run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StartError {
    /// A problem located in the scene file, shown with its place and a fix.
    File(FileError),
    /// Anything else, one line with its context.
    Message(String),
}

impl From<StartError> for crate::Error {
    fn from(e: StartError) -> Self {
        match e {
            StartError::File(e) => crate::Error::File(e),
            StartError::Message(m) => crate::Error::Message(m),
        }
    }
}

impl fmt::Display for StartError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StartError::File(e) => write!(f, "{e}"),
            StartError::Message(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for StartError {}

impl From<FileError> for StartError {
    fn from(e: FileError) -> Self {
        StartError::File(e)
    }
}

impl From<ReadError> for StartError {
    fn from(e: ReadError) -> Self {
        StartError::Message(e.to_string())
    }
}

/// Reads and parses the scene at `path` and creates its output directory: `out_dir`, or by
/// default `out/SCENE_NAME` followed by `default_subdir` (`rovib run` uses none, `rovib bench`
/// `bench`).
pub fn load_scene(path: &Path, out_dir: Option<&Path>, default_subdir: &str) -> Result<(Scene, PathBuf), StartError> {
    let text = read_text_capped(path, MAX_INPUT_BYTES)?;
    let scene = parse_scene(&path.display().to_string(), &text)?;
    let out_dir = match out_dir {
        Some(d) => d.to_owned(),
        None => Path::new("out").join(path.file_stem().unwrap_or_default()).join(default_subdir),
    };
    std::fs::create_dir_all(&out_dir)
        .map_err(|e| StartError::Message(format!("cannot create {}: {e}", out_dir.display())))?;
    Ok((scene, out_dir))
}

/// Where a run starts: the body-formulation state a run integrates from, the same as a
/// phase-space state, and the centre-of-mass motion (bohr, bohr/a.u.).
pub struct Start<const N: usize> {
    /// The start as a run integrates it: q, p, the orientation as a quaternion and the body-frame
    /// J. Defined at every orientation, θ = 0 included.
    pub body: BodyState<N>,
    /// The same start in Euler angles and their momenta, for output and the Euler-angle
    /// formulations (`p_e = Mᵀ J` is defined everywhere; at θ = 0 or π, `J = W p_e` is not, so
    /// the Euler-angle Hamiltonian cannot be evaluated there: use `body`).
    pub state: PhaseState<N>,
    /// Centre-of-mass position.
    pub com_position: Vector3<f64>,
    /// Centre-of-mass velocity.
    pub com_velocity: Vector3<f64>,
    /// For a lab-form start at a geometry where the internal chart is singular (exactly linear):
    /// the positions and velocities about the centre of mass (flat, `LabState::write_to`), from
    /// which `rovib run` starts in the Cartesian chart exactly. There `body` holds only the
    /// projections (a bending velocity out of the body frame's bend plane has no image in
    /// `(ω, q̇)` at linear, so it is not in `p` or `J`).
    pub lab_start: Option<Vec<f64>>,
}

/// The index of `name` among `known`, or an error at the name's place in the file: `message`
/// says what is unknown, `help` is given the known names (the one "unknown name, these are the
/// known ones" answer of scene binding).
pub fn find_name(
    src: &Source<'_>,
    known: &[&str],
    name: &toml::Spanned<String>,
    message: impl FnOnce() -> String,
    help: impl FnOnce(&[&str]) -> String,
) -> Result<usize, FileError> {
    known.iter().position(|k| *k == name.get_ref()).ok_or_else(|| src.error(name.span(), message(), help(known)))
}

/// Binds the scene's initial condition to molecule `m`: names to indices, the scene's units to
/// atomic units, velocities to momenta (the Legendre map), lab-frame positions and velocities to
/// q, p, the orientation and J (a mass-weighted fit, [`frames::from_lab_body`](crate::runtime::frames::from_lab_body)).
pub fn initial_state<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
) -> Result<Start<N>, FileError> {
    let src = scene.source();
    match &scene.initial {
        Initial::Internal { q, momenta, euler, rotation } => {
            let coords = Coordinates::of(m, scene, &src);
            let qv = coords.initial_q(q)?;
            let euler = Vector3::from(*euler);
            let (pv, j) = coords.initial_momenta(&qv, &euler, momenta, rotation)?;
            let body = BodyState { q: qv, p: pv, orientation: quaternion_of_euler(&euler), j };
            Ok(Start {
                body,
                state: PhaseState { q: qv, p: pv, euler, pe: euler_momenta_from_angular_momentum(&euler, &j) },
                com_position: Vector3::zeros(),
                com_velocity: Vector3::zeros(),
                lab_start: None,
            })
        }
        Initial::Lab { positions, velocities, span } => {
            let lab = lab_state(m, &src, positions, velocities, span)?;
            // Before the fit: a huge velocity would only make the fit's numbers overflow.
            let com = lab.centre_of_mass(&m.masses());
            check_centre_of_mass(&src, span, com.position, com.velocity, scene.t_end)?;
            fit_lab_start(m, &src, &lab, span)
        }
    }
}

/// The molecule's coordinates as an internal-form initial condition names them.
struct Coordinates<'a, M, const N: usize, const NA: usize> {
    m: &'a M,
    scene: &'a Scene,
    src: &'a Source<'a>,
    coords: [crate::runtime::Coordinate; N],
    names: Vec<&'static str>,
}

impl<'a, M: Molecule<N, NA>, const N: usize, const NA: usize> Coordinates<'a, M, N, NA> {
    fn of(m: &'a M, scene: &'a Scene, src: &'a Source<'a>) -> Self {
        let coords = m.coordinates();
        let names = coords.iter().map(|c| c.name).collect();
        Coordinates { m, scene, src, coords, names }
    }

    /// The index of coordinate `name`, given in `what` (`q`, `p` or `qdot`).
    fn index(&self, name: &toml::Spanned<String>, what: &str) -> Result<usize, FileError> {
        let m = self.m;
        find_name(
            self.src,
            &self.names,
            name,
            || format!("{} has no coordinate `{}` (in {what})", m.name(), name.get_ref()),
            |known| {
                if known.is_empty() {
                    format!("{} is rigid: remove {what}", m.name())
                } else {
                    format!("the coordinates of {} are {}", m.name(), known.join(", "))
                }
            },
        )
    }

    /// q in atomic units: the given values, each within its coordinate's range, and the
    /// reference geometry's for those not given.
    fn initial_q(&self, q: &[Named<f64>]) -> Result<SVector<f64, N>, FileError> {
        let (coords, units) = (&self.coords, &self.scene.units);
        let mut qv = SVector::<f64, N>::zeros();
        let mut given = [false; N];
        for (name, value) in q {
            let k = self.index(name, "q")?;
            qv[k] = units.coordinate_to_au(coords[k].unit, *value);
            given[k] = true;
            // Outside its range a coordinate describes a mirror image or no geometry at all
            // (a negative bond length); only the start is checked, a run may leave it.
            if !coords[k].contains(qv[k]) {
                let per_au = 1.0 / units.coordinate_to_au(coords[k].unit, 1.0);
                let (low, high) = (coords[k].range.0 * per_au, coords[k].range.1 * per_au);
                return Err(self.src.error(
                    name.span(),
                    format!("{} = {value} is outside its valid range [{low}, {high}]", coords[k].name),
                    format!("give {} a value in [{low}, {high}] (the scene's units)", coords[k].name),
                ));
            }
        }
        if let Some(k) = (0..N).find(|&k| !given[k]) {
            let m = self.m;
            let reference = m.reference_geometry().ok_or_else(|| {
                self.src.error(
                    self.scene.molecule.span(),
                    format!(
                        "the initial q does not give `{}` and {} has no reference geometry",
                        coords[k].name,
                        m.name()
                    ),
                    format!("give every coordinate in q = {{ ... }}, or add `reference` values to {}", m.source()),
                )
            })?;
            for k in (0..N).filter(|&k| !given[k]) {
                qv[k] = reference[k];
            }
        }
        Ok(qv)
    }

    /// p and the body-frame J at `qv`, from the given momenta or velocities and J or p_e.
    fn initial_momenta(
        &self,
        qv: &SVector<f64, N>,
        euler: &Vector3<f64>,
        momenta: &Momenta,
        rotation: &InitialAngularMomentum,
    ) -> Result<(SVector<f64, N>, Vector3<f64>), FileError> {
        let j_of = |rot: &InitialAngularMomentum| match rot {
            InitialAngularMomentum::Pe(pe) => j_of_pe(self.src, euler, pe),
            InitialAngularMomentum::J(j) => Ok(Vector3::from(*j)),
        };
        match momenta {
            Momenta::P(p) => {
                let mut pv = SVector::<f64, N>::zeros();
                for (name, value) in p {
                    pv[self.index(name, "p")?] = *value;
                }
                Ok((pv, j_of(rotation)?))
            }
            Momenta::Qdot(qd) => {
                let mut qdot = SVector::<f64, N>::zeros();
                for (name, value) in qd {
                    let k = self.index(name, "qdot")?;
                    qdot[k] = self.scene.units.velocity_to_au(self.coords[k].unit, *value);
                }
                let j = j_of(rotation)?;
                Ok((self.momenta_of_velocities(qv, &qdot, &j)?, j))
            }
        }
    }

    /// p from q̇ and J: ω = I⁻¹(J − A q̇) and p = Aᵀω + a q̇.
    fn momenta_of_velocities(
        &self,
        qv: &SVector<f64, N>,
        qdot: &SVector<f64, N>,
        j: &Vector3<f64>,
    ) -> Result<SVector<f64, N>, FileError> {
        let m = self.m;
        let mut k = KineticMatrices::<N>::default();
        m.kinetic(qv, &mut k);
        let inertia = k.inertia.cholesky().ok_or_else(|| {
            self.src.whole_file(
                format!(
                    "the inertia tensor of {} is singular at the initial geometry q = {:?}",
                    m.name(),
                    qv.as_slice()
                ),
                "start from a geometry where the molecule is not linear",
            )
        })?;
        let omega = inertia.solve(&(j - k.coriolis * qdot));
        let (_, pv) = momenta_from_velocities(&k, &omega, qdot);
        Ok(pv)
    }
}

/// J from the Euler-angle momenta p_e: W p_e, which the scene parser has checked is defined
/// when p_e ≠ 0.
fn j_of_pe(src: &Source<'_>, euler: &Vector3<f64>, pe: &[f64; 3]) -> Result<Vector3<f64>, FileError> {
    if *pe == [0.0; 3] {
        return Ok(Vector3::zeros());
    }
    Ok(w_matrix(euler)
        .map_err(|e| src.whole_file(format!("the initial orientation: {e}"), "give j instead of pe at θ = 0 or π"))?
        * Vector3::from(*pe))
}

/// The lab-frame positions (every atom's) and velocities, keyed by atom label.
fn lab_state<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    src: &Source<'_>,
    positions: &[Named<[f64; 3]>],
    velocities: &[Named<[f64; 3]>],
    span: &Range<usize>,
) -> Result<LabState<NA>, FileError> {
    let atoms = m.atoms();
    let labels: Vec<&str> = atoms.iter().map(|a| a.label).collect();
    let atom_index = |label: &toml::Spanned<String>, what: &str| -> Result<usize, FileError> {
        find_name(
            src,
            &labels,
            label,
            || format!("{} has no atom `{}` (in {what})", m.name(), label.get_ref()),
            |known| format!("the atoms of {} are {}", m.name(), known.join(", ")),
        )
    };
    let mut lab = LabState::<NA> { positions: SMatrix::zeros(), velocities: SMatrix::zeros() };
    let mut given = [false; NA];
    for (label, x) in positions {
        let i = atom_index(label, "positions")?;
        lab.positions.set_column(i, &Vector3::from(*x));
        given[i] = true;
    }
    let missing: Vec<&str> = (0..NA).filter(|&i| !given[i]).map(|i| atoms[i].label).collect();
    if !missing.is_empty() {
        return Err(src.error(
            span.clone(),
            format!(
                "the lab-frame positions do not give atom{} {}",
                if missing.len() == 1 { "" } else { "s" },
                missing.join(", ")
            ),
            "give the position of every atom, keyed by its label",
        ));
    }
    for (label, v) in velocities {
        lab.velocities.set_column(atom_index(label, "velocities")?, &Vector3::from(*v));
    }
    Ok(lab)
}

/// The start fitted to a lab-frame state. At a linear geometry the fit's velocity report needs
/// the (singular) metric; a molecule with closed forms q(x) takes the projections instead
/// (`rovib run` then starts in the Cartesian chart).
fn fit_lab_start<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    src: &Source<'_>,
    lab: &LabState<NA>,
    span: &Range<usize>,
) -> Result<Start<N>, FileError> {
    let mut lab_start = None;
    let fitted = match from_lab_body(m, lab, &FitOptions::default()) {
        Err(FrameError::SingularMetric { .. }) => {
            let near = m.reference_geometry().unwrap_or_else(SVector::zeros);
            body_of_lab_exact(m, lab, &near).map(|(body, com)| {
                let mut about = *lab;
                for i in 0..NA {
                    about.positions.set_column(i, &(lab.positions.column(i) - com.position));
                    about.velocities.set_column(i, &(lab.velocities.column(i) - com.velocity));
                }
                let mut y = vec![0.0; 6 * NA];
                about.write_to(&mut y);
                lab_start = Some(y);
                (body, com, ())
            })
        }
        other => other.map(|(body, com, _)| (body, com, ())),
    };
    let (body, com, _) = fitted.map_err(|e| {
        src.error(
            span.clone(),
            format!("the lab-frame positions cannot start a run of {}: {e}", m.name()),
            "check the atom positions and their units",
        )
    })?;
    Ok(Start { body, state: body.to_phase(), com_position: com.position, com_velocity: com.velocity, lab_start })
}

/// The speed of light in atomic units (bohr per ħ/E_h): 1/α = 137.036.
pub const SPEED_OF_LIGHT_AU: f64 = 137.035_999_084;

/// The farthest the centre of mass may travel from the origin during a run, bohr (about 5 cm):
/// lab.xyz writes positions with 12 decimals, and beyond this they are digits of nothing.
pub const MAX_LAB_DISTANCE: f64 = 1e9;

/// The centre of mass of a lab-frame start must move slower than light and stay within
/// [`MAX_LAB_DISTANCE`] of the origin until `t_end` (a.u.): an infinite or huge velocity would
/// write `inf` or hundreds of digits into lab.xyz.
fn check_centre_of_mass(
    src: &Source<'_>,
    span: &Range<usize>,
    position: Vector3<f64>,
    velocity: Vector3<f64>,
    t_end: f64,
) -> Result<(), FileError> {
    let speed = velocity.norm();
    if speed.is_nan() || speed >= SPEED_OF_LIGHT_AU {
        return Err(src.error(
            span.clone(),
            format!(
                "the centre of mass moves at {} bohr per ħ/E_h, not slower than light ({SPEED_OF_LIGHT_AU})",
                Compact(speed)
            ),
            "check the velocities and their unit (the scene's length per its time unit); a classical run needs \
             speeds far below light",
        ));
    }
    let farthest = position.norm() + speed * t_end;
    if farthest.is_nan() || farthest > MAX_LAB_DISTANCE {
        return Err(src.error(
            span.clone(),
            format!(
                "the centre of mass would reach {} bohr from the origin by the end of the run, more than {}",
                Compact(farthest),
                Compact(MAX_LAB_DISTANCE)
            ),
            "centre the positions nearer the origin or remove the common velocity (it does not change the \
             molecule's motion)",
        ));
    }
    Ok(())
}

/// The coordinates the scene's `run.frozen` names, frozen (rotation free); an unknown name is
/// an error at its place in the scene.
pub fn frozen_reduction<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
) -> Result<Reduction<N>, FileError> {
    let names: Vec<&str> = scene.frozen.iter().map(|s| s.get_ref().as_str()).collect();
    Reduction::freezing(m, &names).map_err(|e| {
        let at = match &e {
            ReductionError::UnknownCoordinate { name, .. } => {
                scene.frozen.iter().find(|s| s.get_ref() == name).map_or(0..0, |s| s.span())
            }
            _ => 0..0,
        };
        scene.source().error(at, e.to_string(), "name coordinates from `rovib list` in run.frozen")
    })
}

/// The system every command integrates, chosen from the scene: the body formulation (no
/// gimbal lock) on the fast path, reduced to what the scene needs: frozen coordinates as it
/// names them, `J = 0` when the initial angular momentum is exactly zero (then `J` stays
/// zero), and the orientation only when an output needs it or when nothing else would be
/// integrated (a rigid molecule at rest, or everything frozen with J = 0: the solver then
/// carries the constant orientation, so that the run still has its output times and summary).
/// Returns the system and the initial flat state.
pub fn production_system<'m, M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &'m M,
    scene: &Scene,
    start: &BodyState<N>,
) -> Result<(ReducedSystem<'m, M, N, NA>, Vec<f64>), StartError> {
    let (system, y0) = production_system_unchecked(m, scene, start)?;
    // H(0) before anything is written: the kinetic metric must be invertible and the energy
    // finite at the start (the same evaluation the run makes at its first output time).
    system.energy(&y0).map_err(|e| StartError::Message(format!("the initial state: {e}")))?;
    Ok((system, y0))
}

/// [`production_system`] without its check that the kinetic metric is invertible at the start:
/// for a run that starts at a linear geometry in the Cartesian chart (`rovib run`'s chart
/// switch), which checks the start there instead.
pub fn production_system_unchecked<'m, M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &'m M,
    scene: &Scene,
    start: &BodyState<N>,
) -> Result<(ReducedSystem<'m, M, N, NA>, Vec<f64>), StartError> {
    let mut reduction = frozen_reduction(m, scene)?;
    if start.j == Vector3::zeros() {
        let orientation = scene.outputs.files.needs().orientation() || reduction.active_count() == 0;
        reduction.rotation = RotationPart::ZeroAngularMomentum { orientation };
    }
    let system = ReducedSystem::from_body(m, reduction, start).with_min_pivot(scene.min_metric_pivot);
    let mut y0 = vec![0.0; system.dim()];
    system.reduce_body(start, &mut y0).map_err(|e| StartError::Message(format!("the initial state: {e}")))?;
    Ok((system, y0))
}

/// A stop condition bound to the molecule: coordinate index, name, bounds in atomic units.
pub type StopCondition = (usize, &'static str, [f64; 2]);

/// `run.stop_outside` bound to the molecule; an unknown name is an error at its place (also
/// used by ensembles, per trajectory).
pub fn stop_conditions<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
) -> Result<Vec<StopCondition>, FileError> {
    let coords = m.coordinates();
    let names: Vec<&str> = coords.iter().map(|c| c.name).collect();
    scene
        .stop_outside
        .iter()
        .map(|(name, [low, high])| {
            let k = find_name(
                &scene.source(),
                &names,
                name,
                || format!("{} has no coordinate `{}` (in run.stop_outside)", m.name(), name.get_ref()),
                |known| format!("the coordinates of {} are {}", m.name(), known.join(", ")),
            )?;
            let to_au = |x: f64| scene.units.coordinate_to_au(coords[k].unit, x);
            Ok((k, coords[k].name, [to_au(*low), to_au(*high)]))
        })
        .collect()
}
