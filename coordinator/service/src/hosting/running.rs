//! A hosted campaign's life on its thread: started live, run to its end (retrying while no
//! worker can serve it, stopping when cancelled), closed with its result and plots, its
//! record marked.

use super::*;

impl Campaigns {
    /// Run `campaign` as a live campaign, on a thread of its own.
    pub(super) fn start(
        self: &Arc<Self>,
        live: &mut HashMap<CampaignId, Arc<Live>>,
        id: CampaignId,
        campaign: Campaign,
    ) -> Result<()> {
        let mut first = Snapshot::running(&hex(&id), &campaign.name);
        first.free = campaign.free.iter().map(|p| p.name.clone()).collect();
        first.message = self.store.campaign(&id)?.and_then(|r| r.message);
        let (state, _) = watch::channel(first);
        let entry = Arc::new(Live {
            cancel: AtomicBool::new(false),
            state,
        });
        live.insert(id, entry.clone());
        let this = self.clone();
        std::thread::Builder::new()
            .name(format!("campaign {}", campaign.name))
            .spawn(move || this.run(id, campaign, entry))
            .map_err(|e| Error::Dispatch(format!("cannot start a campaign thread: {e}")))?;
        Ok(())
    }

    /// Run a campaign to its end, retrying while no worker can serve it.
    fn run(&self, id: CampaignId, campaign: Campaign, live: Arc<Live>) {
        let outcome = self.calibrate_until_served(&campaign, &live);
        self.conclude(&id, &campaign, &live, outcome);
        drop(campaign);
        crate::memory::return_freed();
    }

    /// Calibrate `campaign` live, waiting (the pause doubling up to `MAX_PAUSE`) and starting
    /// again while no worker can serve it: an absent fleet is not the campaign's failure.
    fn calibrate_until_served(&self, campaign: &Campaign, live: &Live) -> Result<Calibration> {
        let progress = LiveProgress {
            live,
            evaluations: AtomicU64::new(0),
        };
        let mut pause = Duration::from_secs(1);
        loop {
            // Each try counts its own evaluations, through the coordinator's dispatcher.
            let stored = self.dispatcher.evaluator();
            let evaluator = Cancellable {
                inner: &stored,
                cancel: &live.cancel,
            };
            progress.evaluations.store(0, Ordering::SeqCst);
            // A run again replays the store from the start: so does its progress.
            live.state.send_modify(|s| {
                s.history = History::default();
                s.runs.clear();
                s.run_best.clear();
            });
            match calibration::calibrate_through(campaign, &evaluator, &*self.store, &progress) {
                Err(Error::Fault(fault)) if fault.kind == FaultKind::Unavailable => {
                    tracing::warn!(campaign = %campaign.name, error = %fault, "waiting for workers");
                    live.state
                        .send_modify(|s| s.failure = Some(format!("waiting for workers: {fault}")));
                    let until = std::time::Instant::now() + pause;
                    while std::time::Instant::now() < until && !live.cancel.load(Ordering::SeqCst) {
                        std::thread::sleep(Duration::from_millis(50));
                    }
                    if live.cancel.load(Ordering::SeqCst) {
                        break Err(Error::Fault(Fault::cancelled("campaign cancelled")));
                    }
                    pause = (pause * 2).min(MAX_PAUSE);
                }
                other => break other,
            }
        }
    }

    /// Show and record how the campaign ended: finished (its result and plots), cancelled
    /// or failed (its public failure).
    fn conclude(
        &self,
        id: &CampaignId,
        campaign: &Campaign,
        live: &Live,
        outcome: Result<Calibration>,
    ) {
        match outcome {
            Ok(c) => {
                let plots = self.report(id, &c);
                live.state.send_modify(|s| {
                    s.run_best = c.runs.iter().map(|r| r.objective).collect();
                    s.best_objective = c.best_run().objective;
                    let evaluations = c.evaluations() as u64;
                    s.evaluations = s.evaluations.max(evaluations);
                    s.history.record(evaluations, &s.run_best);
                    s.runs = c.run_bests();
                    s.result = Some(c.outcome.clone());
                    s.plots = plots;
                });
                let kept = live.state.borrow().clone();
                if let Err(e) = self.close(id, None, &kept) {
                    tracing::error!(error = %e, "cannot record the campaign's progress");
                }
                live.state.send_modify(|s| {
                    s.phase = Phase::Finished;
                    s.failure = None;
                });
            }
            Err(Error::Fault(fault)) if fault.kind == FaultKind::Cancelled => {
                let kept = live.state.borrow().clone();
                if let Err(e) = self.close(id, Some((CampaignStatus::Cancelled, None)), &kept) {
                    tracing::error!(error = %e, "cannot record the cancellation");
                }
                live.state.send_modify(|s| {
                    s.phase = Phase::Cancelled;
                    s.failure = None;
                });
                tracing::info!(campaign = %campaign.name, "campaign cancelled");
            }
            Err(e) => {
                tracing::error!(campaign = %campaign.name, error = %e, "campaign failed");
                let failure = self.public(&e.to_string());
                let kept = live.state.borrow().clone();
                let _ = self.close(
                    id,
                    Some((CampaignStatus::Failed, Some(failure.clone()))),
                    &kept,
                );
                live.state.send_modify(|s| {
                    s.phase = Phase::Failed;
                    s.failure = Some(failure);
                });
            }
        }
    }

    /// Keep in the record of a live campaign that ended what it knows: its progress
    /// history and, when it did not finish (a finished calibration wrote its runs), each
    /// run's best so far; with its new `status` and failure when one is given.
    fn close(
        &self,
        id: &CampaignId,
        status: Option<(CampaignStatus, Option<String>)>,
        s: &Snapshot,
    ) -> Result<()> {
        let _guard = self.records.lock().expect("records lock");
        if let Some(mut record) = self.store.campaign(id)? {
            record.history = s.history.points().to_vec();
            if record.free.is_empty() {
                record.free = s.free.clone();
            }
            if let Some((status, failure)) = status {
                record.status = status;
                record.failure = failure;
                // Runs that evaluated nothing have no point to keep.
                record.runs = s
                    .runs
                    .iter()
                    .filter(|r| r.objective.is_finite())
                    .cloned()
                    .collect();
            }
            self.store.put_campaign(id, &record)?;
        }
        Ok(())
    }

    /// Write the finished campaign's result.json and plots to `<results>/<id>/`; the plots'
    /// text.
    fn report(&self, id: &CampaignId, c: &Calibration) -> Vec<(String, String)> {
        let folder = self.results.join(hex(id));
        let mut plots = Vec::new();
        match report::write(c, &folder) {
            Ok(paths) => {
                for path in paths {
                    let is_svg = path.extension().is_some_and(|e| e == "svg");
                    if let (true, Ok(text)) = (is_svg, std::fs::read_to_string(&path)) {
                        let name = path.file_name().unwrap_or_default().to_string_lossy();
                        plots.push((name.into_owned(), text));
                    }
                }
            }
            Err(e) => tracing::error!(error = %e, "cannot write the campaign's results"),
        }
        plots
    }

    pub(super) fn mark(
        &self,
        id: &CampaignId,
        status: CampaignStatus,
        failure: Option<String>,
    ) -> Result<()> {
        let _guard = self.records.lock().expect("records lock");
        if let Some(mut record) = self.store.campaign(id)? {
            record.status = status;
            record.failure = failure;
            self.store.put_campaign(id, &record)?;
        }
        Ok(())
    }
}

/// Counts a live campaign's evaluations and each run's best into its state.
///
/// The count is added to under the state's lock, so the states clients see count up in the
/// order they are sent; and what they see never goes back: a calibration started again
/// (its workers were gone) replays the store from its start, and its count shows once it
/// passes what was shown.
struct LiveProgress<'a> {
    live: &'a Live,
    /// Evaluations of this attempt of the calibration.
    evaluations: AtomicU64,
}

impl LiveProgress<'_> {
    /// Add `count` to the attempt's evaluations, within the state's lock: the new total,
    /// and the state's (never lower than before).
    fn count(&self, s: &mut Snapshot, count: usize) -> u64 {
        let total = self.evaluations.fetch_add(count as u64, Ordering::SeqCst) + count as u64;
        s.evaluations = s.evaluations.max(total);
        total
    }
}

impl Progress for LiveProgress<'_> {
    fn evaluated(&self, count: usize, best_objective: f64) {
        self.live.state.send_modify(|s| {
            let total = self.count(s, count);
            s.best_objective = s.best_objective.min(best_objective);
            s.history.record(total, &s.run_best);
        });
    }

    fn run_evaluated(&self, run: usize, count: usize, run_best_objective: f64) {
        self.live.state.send_modify(|s| {
            let total = self.count(s, count);
            if s.run_best.len() <= run {
                s.run_best.resize(run + 1, f64::INFINITY);
            }
            s.run_best[run] = s.run_best[run].min(run_best_objective);
            s.best_objective = s.best_objective.min(run_best_objective);
            if let Some(r) = s.runs.get_mut(run) {
                r.evaluations += count;
            }
            s.history.record(total, &s.run_best);
        });
    }

    fn planned(&self, runs: &[(String, usize)]) {
        self.live.state.send_modify(|s| {
            s.runs = runs
                .iter()
                .map(|(method, start)| RunBest {
                    method: method.clone(),
                    start: *start,
                    point: Vec::new(),
                    objective: f64::INFINITY,
                    evaluations: 0,
                    rounds: 0,
                })
                .collect();
        });
    }

    fn run_round(&self, run: usize) {
        self.live.state.send_modify(|s| {
            if let Some(r) = s.runs.get_mut(run) {
                r.rounds += 1;
            }
        });
    }

    fn run_improved(&self, run: usize, point: &[f64], objective: f64) {
        self.live.state.send_modify(|s| {
            if let Some(r) = s.runs.get_mut(run) {
                if objective < r.objective {
                    r.objective = objective;
                    r.point = point.to_vec();
                }
            }
        });
    }
}

/// An evaluator that refuses every ask once its campaign is cancelled.
struct Cancellable<'a, E: ?Sized> {
    inner: &'a E,
    cancel: &'a AtomicBool,
}

impl<E: Evaluator + ?Sized> Evaluator for Cancellable<'_, E> {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> std::result::Result<Vec<Evaluation>, Fault> {
        if self.cancel.load(Ordering::SeqCst) {
            return Err(Fault::cancelled("campaign cancelled"));
        }
        self.inner.evaluate(objective, points)
    }

    fn has_room(&self) -> bool {
        self.inner.has_room()
    }

    fn release(&self, objective: &Objective) {
        self.inner.release(objective)
    }
}

impl<S: Stored + ?Sized> Stored for Cancellable<'_, S> {
    fn stats(&self) -> CacheStats {
        self.inner.stats()
    }

    fn error(&self) -> Option<StoreError> {
        self.inner.error()
    }
}
