//! Cycle 451 MEASURE KINEMATICS: the calibration sphere measured at several angles of
//! each rotary axis, compared with the active kinematic model, and (modes 1..3) the
//! model corrected (spec.md, "Cycle 451"; seeds 000, 001, 004).
//!
//! # Sequence
//!
//! Each step has its file: [`parameters`] (typed at parse time), [`plan`](mod@plan), [`measure`],
//! [`identify`], [`evaluate`], [`report`], [`write_back`] and the [`measuring_log`].
//!
//! 1. Q431 = 1/3, locate: the probe stands roughly over the sphere, about Q320 + SET_UP
//!    above it (an `L` block or the operator put it there). It probes down along the
//!    tool axis, then measures the sphere around that estimate, which becomes the
//!    preset; with the axes not moved since, that measurement is the first axis's
//!    reference. With a rotary axis off 0 the axes then turn to 0 and the sphere is
//!    measured again there: that is the preset (not the located centre carried to 0
//!    through the active kinematics, whose errors the cycle measures). Q431 = 0/2:
//!    the sphere centre is the active datum (preset table row plus shift,
//!    [`crate::datum`]); the probe goes there from wherever it stands, up to the safe
//!    height, over, down, probes the pole and locates the sphere from that contact
//!    (first pass only): a sphere further from the datum than the cycle can measure
//!    around it stops the cycle, and every probe that misses names the preset.
//!    Q431 = 2/3 set the preset to the centre at the reference after measuring; the
//!    active row of the preset table is written in modes 1..3 once everything else
//!    succeeded.
//! 2. Per measured axis, in the order A, B, C: the 0 deg reference first, then the
//!    measuring positions ([`crate::kinematics::positions`]); the other rotary axes stand
//!    at their incidence angles (Q413/Q417/Q421). Between positions the probe retracts to
//!    Q408 above the preset and over the preset in the working plane before the rotary
//!    axes turn at Q253; with Q408 = 0 it rises along the tool axis to the lowest height
//!    that clears the sphere at every angle of the turn (refused with a Hirth axis).
//!    Either way the approach starts only after the axes stand at the measurement's
//!    angles. Moves toward the sphere along the tool axis run at min(Q253, FMAX) (the
//!    approach to the probing height), every other linear move at the probe table's FMAX.
//! 3. Sphere measurement: the pole along the (possibly tilted) tool axis, then Q423
//!    points around the equator in the working plane from Q380, radially toward the
//!    centre; a sphere with free radius through the latched X/Y/Z positions (each
//!    measurement its own run id, fitted by the [`crate::kinematics::Estimator`]). When the fit moved the
//!    centre by more than [`measure::RE_PROBE_TOLERANCE`] from where it was expected, the sphere is
//!    probed once more around the new centre; the radius of the last round must be Q407
//!    within `maxDevCalBall`.
//! 4. Q432 != 0: every position is measured twice, approached from angle + Q432 and from
//!    angle - Q432; the identification uses the mean, the backlash is the mean tangential
//!    difference over the measuring circle radius (not for radii < 1 mm or Hirth axes).
//! 5. Identification ([`crate::kinematics::identification`]) by the estimator, results
//!    (Q141..Q149, QS144..QS146), protocol `TCHPRAUTO.html`, and for modes 1..3 the
//!    corrected errors written through [`crate::kinematics_file::ActiveKinematics::write`]: only after all of that
//!    succeeded, and beyond `maxModification` only when confirmed.

pub mod dry_run;
pub mod evaluate;
pub mod identify;
pub mod measure;
pub mod measuring_log;
pub mod parameters;
pub mod plan;
pub mod report;
pub mod rotary_m_function;
pub mod write_back;

pub use parameters::{AxisRange, Feed, KinematicsParams};
pub use plan::{plan, plan_on, AxisPlan, KinematicsPlan, PlanError, PlanErrorKind};
pub use report::{AxisReport, KinematicsReport, PositionReport, SphereRecord};

use crate::cycle::{CycleContext, MeasuringCycle};
use crate::cycle_block::CycleBlock;
use crate::error::CycleError;
use crate::kinematics::error_uncertainty;
use crate::kinematics::model::{ErrorSet, KinematicModel};
use crate::kinematics_file::ActiveKinematics;
use crate::results::CycleOutput;
use evaluate::Evaluation;
use hal::Machine;
use measure::{arr, axis_map, Measure};
use report::preset_words;
use write_back::WriteBack;

impl MeasuringCycle for KinematicsParams {
    fn run<M: Machine>(
        &self,
        call: &CycleBlock,
        machine: &mut M,
        ctx: &mut CycleContext<'_>,
    ) -> Result<CycleOutput, CycleError> {
        let cfg = ctx.cfg;
        let plan = plan::plan_on(self, &call.tool.probe, cfg)
            .map_err(|e| CycleError::Plan(e.to_string()))?;
        if let Some(m) = plan.rotary_m {
            rotary_m_function::check_start(machine, &plan, m, ctx, call.block)?;
        }
        let active = ActiveKinematics::load(&ctx.kinematics, &cfg.machine)
            .map_err(|e| CycleError::Plan(format!("active kinematics: {e}")))?;
        let active_set = ErrorSet::from_map(&active.errors);
        let model = KinematicModel::new(&plan.chain, &active_set);
        let mut m = Measure::new(machine, ctx, &plan, call, model)?;
        let preset_before = m.preset;
        let p = &plan.params;
        // Q431 = 1/3: the probe stands over the sphere, which is located from there;
        // 0/2: the sphere is at the active datum.
        if p.preset == 1 || p.preset == 3 {
            m.locate()?;
        } else {
            m.approach_datum()?;
        }
        let preset_measuring = m.preset;
        let measured = m.measure_axes()?;
        let spheres = m.spheres;
        let rotary_targets = std::mem::take(&mut m.rotary_targets);

        let input = identify::input(&plan, active_set, &measured);
        let result = identify::identify(m.ctx.estimator, &input)?;
        let estimator = m.ctx.estimator.name();
        let tool = (call.tool.axis, call.tool.probe.repeatability());
        let u = identify::uncertainty(&plan, &m.model, tool, &measured, &input, &result)?;
        let errors_u = error_uncertainty::by_name(&u);

        let ev = Evaluation {
            plan: &plan,
            model: &m.model,
            input: &input,
            result: &result,
        };
        let mut notes = std::mem::take(&mut m.notes);
        let axes = measured
            .iter()
            .map(|(gi, positions)| ev.axis_report(&plan.axes[*gi], positions, &mut notes))
            .collect::<Result<Vec<_>, _>>()?;
        let axes = with_uncertainties(axes, &errors_u);
        let offset = ev.reference_ball() - preset_measuring;
        let (mut q, qs) = ev.results(&axes, &offset);
        // mStrobeRotAxPos: Q120..Q122 as the last strobe left them, the program's to read.
        q.extend(rotary_targets);
        // Q431 = 2/3: the preset goes to the sphere centre measured at the reference.
        let mut preset_after = m.preset;
        if p.preset == 2 || p.preset == 3 {
            preset_after = ev.reference_ball();
            m.note(format!(
                "Q431={}: {} X{:+.4} Y{:+.4} Z{:+.4}",
                p.preset,
                preset_words(p.mode.writes()),
                preset_after.x,
                preset_after.y,
                preset_after.z
            ));
        }
        notes.push(format!("{spheres} sphere(s) measured"));
        notes.extend(result.transfers.iter().map(transfer_note));
        let now_ns = m.clock_ns();
        let ctx = m.ctx;
        let machine_time = ctx.machine_time_at(now_ns);

        let write_back = WriteBack::decide(
            call.block,
            p.mode,
            &result,
            cfg.parameters.max_modification,
            ctx,
        );
        if !p.mode.writes() {
            notes.push("mode 0 (check): the kinematics were not changed".into());
        }
        let mut report = KinematicsReport {
            mode: p.mode.q406(),
            machine: cfg.machine.name.clone(),
            kinematics_file: ctx.kinematics.clone(),
            estimator,
            probe: call.tool.probe.name.clone(),
            written: false,
            incidence: axis_map(&plan.present, &plan.incidence),
            preset_before: arr(&preset_before),
            preset_after: arr(&preset_after),
            preset_shift: arr(&(preset_after - preset_before)),
            restored: None,
            preset_set: p.preset != 0 && p.mode.writes() && write_back.stop.is_none(),
            preset: preset_text(p, write_back.stop.is_some(), &preset_after),
            offset_error: arr(&offset),
            errors_before: result.before.to_map(&plan.present),
            errors_after: result.after.to_map(&plan.present),
            errors_u,
            axes,
            notes,
            machine_time,
        };
        let log = write_back.write(call.block, &mut report, &active, ctx)?;
        // Q431 != 0: the active preset row takes the sphere centre, written only in
        // modes 1..3 and after the kinematics were accepted (mode 0, a refusal or any
        // failure before this point write neither).
        if p.preset != 0 && p.mode.writes() && write_back.stop.is_none() {
            let shift = ctx.datum.shift;
            let row = [0, 1, 2].map(|i| preset_after[i] - shift[i]);
            ctx.datum.presets.set_active_xyz(row);
            ctx.datum
                .presets
                .write_row(ctx.datum.presets.active, &cfg.machine)
                .map_err(|e| CycleError::Plan(format!("writing the preset table: {e}")))?;
            let file = ctx.datum.presets.path.display().to_string();
            ctx.note(
                call.block,
                format!(
                    "preset {} set to X{:+.4} Y{:+.4} Z{:+.4} in {file} (previous version kept as .prev)",
                    ctx.datum.presets.active, row[0], row[1], row[2]
                ),
            );
        }
        Ok(CycleOutput {
            q,
            qs,
            u: Default::default(),
            stop: write_back.stop,
            kinematics: Some(Box::new(report)),
            calibration: None,
            logs: vec![log],
        })
    }
}

/// Each axis's report with the uncertainties of its own errors.
fn with_uncertainties(
    axes: Vec<AxisReport>,
    errors_u: &std::collections::BTreeMap<String, f64>,
) -> Vec<AxisReport> {
    axes.into_iter()
        .map(|mut a| {
            a.errors_u = errors_u
                .iter()
                .filter(|(name, _)| a.errors_after.contains_key(*name))
                .map(|(n, v)| (n.clone(), *v))
                .collect();
            a
        })
        .collect()
}

/// The preset line of the result: what Q431 did, with the sphere centre.
fn preset_text(p: &KinematicsParams, refused: bool, at: &nalgebra::Vector3<f64>) -> String {
    let words = match p.preset {
        0 => return "Q431=0: the preset is not changed".to_string(),
        _ if p.mode.writes() && refused => {
            "preset not set (the kinematics were not accepted); the sphere centre measured at"
        }
        _ => preset_words(p.mode.writes()),
    };
    format!(
        "Q431={}: {words} X{:+.4} Y{:+.4} Z{:+.4}",
        p.preset, at.x, at.y, at.z
    )
}

/// The note of one rotation moved into a machine datum (mode 3).
fn transfer_note(t: &crate::kinematics::identification::DatumTransfer) -> String {
    format!(
        "machine datum: {} = {:+.6} deg moved into {}",
        ErrorSet::name(t.from),
        t.value,
        ErrorSet::name(t.to)
    )
}
