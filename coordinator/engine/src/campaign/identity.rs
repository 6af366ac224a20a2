//! The identity of a resolved campaign: a hash of everything that changes its result, the
//! key under which the store keeps its evaluations and results.

use super::{Campaign, InputMapping, OutputMapping};
use calib_model::content_hash::ContentHasher;

impl Campaign {
    /// A hash of the resolved campaign run on the measurement with content hash
    /// `measurement_hash`: name, model and version, parameters (fixed and free, with bounds
    /// and nominal values), outputs and weights, window, horizon, search and solver
    /// settings. Two campaigns with the same identity compute the same result; the file's
    /// formatting, comments and location do not count.
    pub fn identity(&self, measurement_hash: &[u8; 32]) -> [u8; 32] {
        let info = self.model.info();
        let mut h = ContentHasher::new(b"calib.campaign.v1\0");
        h.text(&self.name)
            .text(&info.name)
            .bytes(&info.version.to_le_bytes())
            .series(&self.base)
            .series(&[self.stop_time, self.window.0, self.window.1])
            .count(self.free.len());
        for p in &self.free {
            h.count(p.index).series(&[p.nominal, p.min, p.max]);
        }
        h.bytes(measurement_hash).count(self.outputs.len());
        hash_outputs(&mut h, &self.outputs);
        // Inputs, when mapped, change what is simulated; a campaign without them keeps the
        // identity it always had. So do several windows, experiments and parameters free in
        // one experiment alone.
        hash_inputs(&mut h, &self.inputs);
        calib_model::user_effects::hash_into(&mut h, self.model.user_effects());
        if self.windows.len() > 1 {
            h.text("windows").count(self.windows.len());
            for w in &self.windows {
                h.series(&[w.0, w.1]);
            }
        }
        if !self.more.is_empty() || !self.experiment.is_empty() {
            self.hash_experiments(&mut h);
        }
        self.hash_search_and_solver(&mut h);
        h.finish()
    }

    /// The further experiments, and which experiment each free parameter belongs to.
    fn hash_experiments(&self, h: &mut ContentHasher) {
        h.text("experiments")
            .text(&self.experiment)
            .count(self.more.len());
        for e in &self.more {
            h.text(&e.name)
                .text(&e.measurement_file.to_string_lossy())
                .text(&e.time_column)
                .series(&e.base)
                .series(&[e.stop_time])
                .count(e.windows.len());
            for w in &e.windows {
                h.series(&[w.0, w.1]);
            }
            h.count(e.outputs.len());
            hash_outputs(h, &e.outputs);
            h.count(e.inputs.len());
            hash_inputs(h, &e.inputs);
        }
        for p in &self.free {
            h.text(p.experiment.as_deref().unwrap_or(""));
        }
    }

    /// The search's methods, starts, budget and seed, and the solver's settings.
    fn hash_search_and_solver(&self, h: &mut ContentHasher) {
        h.count(self.search.methods.len());
        for m in &self.search.methods {
            h.text(m.name());
        }
        h.count(self.search.starts)
            .count(self.search.max_evaluations)
            .bytes(&self.search.seed.to_le_bytes())
            .count(self.search.extra_starts.len());
        for start in &self.search.extra_starts {
            h.series(start);
        }
        h.series(&[self.solver.rtol, self.solver.atol])
            .count(self.solver.max_steps);
        // The start and the communication step, when set, change what is simulated; a
        // run without them keeps the fingerprint it always had.
        if self.solver.start_time != 0.0 || self.solver.communication_step.is_some() {
            h.text("time settings").series(&[
                self.solver.start_time,
                self.solver.communication_step.unwrap_or(0.0),
            ]);
        }
    }
}

/// Each output compared: its model index, its measured column, its weight and scale.
fn hash_outputs(h: &mut ContentHasher, outputs: &[OutputMapping]) {
    for o in outputs {
        h.count(o.model_index)
            .text(&o.measured)
            .series(&[o.weight])
            .text(o.scale.name());
    }
}

fn hash_inputs(h: &mut ContentHasher, inputs: &[InputMapping]) {
    if !inputs.is_empty() {
        h.text("inputs").count(inputs.len());
        for i in inputs {
            h.count(i.model_index)
                .text(&i.measured)
                .text(i.interpolation.as_str());
        }
    }
}
