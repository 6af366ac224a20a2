//! One round of work for the points of many callers: the runs of a campaign each ask for a
//! point or two at a time (a Nelder–Mead step, a Powell line search), and a request, a
//! store write or a flush per ask costs more than the point's own share of the work.
//! [`Coalescer::evaluate`] gathers what every caller asks while earlier rounds are under way
//! and hands it to one caller as one round. The evaluation store resolves a round's missing
//! points with one lookup, one batch of simulations per objective and one durable write
//! ([`crate::store::StoredEvaluator`]); the gRPC evaluator sends a round as one batch per
//! objective (the service's `GrpcEvaluator`).
//!
//! No timer: a caller that finds no round under way sends one at once (its own points and
//! whatever else waits); a caller that finds one under way sends a second only when the
//! workers have room for it ([`crate::evaluator::Evaluator::has_room`]) and fewer than
//! [`LEADERS`] travel, else it leaves its points in the queue. When a round's answers are in
//! (before the store has made them durable: [`Arrival`]) its leader hands the baton to the
//! first caller still waiting, which sends everything then waiting, and then settles its
//! round and returns to its own work. A lone caller therefore waits for nothing, many
//! callers share rounds, a second round fills idle workers while the first travels, the
//! workers get the next round while the last one is written, and no caller's own work waits
//! while it serves others'. Each point's answer is the answer for that point alone, so how
//! points are grouped changes no number.

use crate::evaluator::Fault;
use crate::objective::Evaluation;
use std::cell::Cell;
use std::sync::{Arc, Condvar, Mutex};

/// Points to send, grouped by key: each group one batch. A point is the values of the free
/// parameters unless the caller attaches more to it (`P`).
pub type Groups<K, P = Vec<f64>> = Vec<(K, Vec<P>)>;

/// Each group's answers (a point each, in order) or the fault that stopped it.
pub type Answers = Vec<Result<Vec<Evaluation>, Fault>>;

/// Rounds under way at once at most: a second fills idle workers while the first's answers
/// travel back. A round that has arrived and handed on the baton settles beside them.
pub const LEADERS: usize = 2;

/// What one caller waits on: its answer, and perhaps first the baton (it leads a round).
struct Reply {
    state: Mutex<ReplyState>,
    ready: Condvar,
}

#[derive(Default)]
struct ReplyState {
    /// Lead the next round (taken once).
    lead: bool,
    answer: Option<Result<Vec<Evaluation>, Fault>>,
}

impl Reply {
    fn new() -> Self {
        Self {
            state: Mutex::new(ReplyState::default()),
            ready: Condvar::new(),
        }
    }

    fn hand_baton(&self) {
        self.state.lock().expect("reply lock").lead = true;
        self.ready.notify_all();
    }

    fn answer(&self, answer: Result<Vec<Evaluation>, Fault>) {
        self.state.lock().expect("reply lock").answer = Some(answer);
        self.ready.notify_all();
    }

    /// The baton (`None`: lead a round) if handed, else the answer once it is in.
    fn wait(&self) -> Option<Result<Vec<Evaluation>, Fault>> {
        let mut state = self.state.lock().expect("reply lock");
        loop {
            if std::mem::take(&mut state.lead) {
                return None;
            }
            if let Some(answer) = state.answer.take() {
                return Some(answer);
            }
            state = self.ready.wait(state).expect("reply lock");
        }
    }
}

/// One caller's points, waiting to be sent.
struct Ask<K, P> {
    key: K,
    points: Vec<P>,
    reply: Arc<Reply>,
    /// Handed the baton already (it will take this round itself).
    leads: bool,
}

struct Queue<K, P> {
    waiting: Vec<Ask<K, P>>,
    /// Rounds travelling (their leaders' places) or handed to a waiting caller.
    leaders: usize,
}

impl<K, P> Queue<K, P> {
    /// Hand the baton to the first caller waiting that has not been handed it; false when
    /// there is none.
    fn pass_baton(&mut self) -> bool {
        match self.waiting.iter_mut().find(|ask| !ask.leads) {
            Some(next) => {
                next.leads = true;
                next.reply.hand_baton();
                true
            }
            None => false,
        }
    }
}

/// Gathers the points of concurrent callers into shared dispatches. `K` names what points
/// may share a request (the objective); points of different keys go in batches of their
/// own, sent side by side.
pub struct Coalescer<K, P = Vec<f64>> {
    queue: Mutex<Queue<K, P>>,
}

impl<K, P> Default for Coalescer<K, P> {
    fn default() -> Self {
        Self {
            queue: Mutex::new(Queue {
                waiting: Vec::new(),
                leaders: 0,
            }),
        }
    }
}

/// Answers the callers of a round that ended without answering them (the dispatch
/// panicked), so that none waits for ever.
struct Unanswered(Vec<Arc<Reply>>);

impl Drop for Unanswered {
    fn drop(&mut self) {
        for reply in &self.0 {
            let unanswered = reply.state.lock().expect("reply lock").answer.is_none();
            if unanswered {
                reply.answer(Err(Fault::unavailable("the dispatch of this batch failed")));
            }
        }
    }
}

/// Handed to a round's `send`: [`Arrival::arrived`] says that the round's answers are in
/// and only their bookkeeping is left (the store writes them durably before they are
/// published), so that a caller waiting for the next round may set out with it while this
/// one settles. A round that never says so has arrived when `send` returns.
pub struct Arrival<'a>(&'a dyn Fn());

impl Arrival<'_> {
    pub fn arrived(&self) {
        (self.0)()
    }
}

/// Ends a leader's round once (on arrival if a caller waits, else when the round is over,
/// also when it panics): the baton goes to a caller still waiting, or the leader's place is
/// given up.
struct EndOfRound<'a, K, P> {
    coalescer: &'a Coalescer<K, P>,
    ended: Cell<bool>,
}

impl<K, P> EndOfRound<'_, K, P> {
    /// On arrival: the baton goes to a caller waiting now. With none waiting the leader
    /// keeps its place while it settles, so that the callers it answers, asking again one
    /// by one, gather into the next round instead of each leading a small one.
    fn arrive(&self) {
        if self.ended.get() {
            return;
        }
        let mut queue = self.coalescer.queue.lock().expect("coalescer lock");
        if queue.pass_baton() {
            self.ended.set(true);
        }
    }

    fn end(&self) {
        if self.ended.replace(true) {
            return;
        }
        let mut queue = match self.coalescer.queue.lock() {
            Ok(queue) => queue,
            Err(poisoned) => poisoned.into_inner(),
        };
        if !queue.pass_baton() {
            queue.leaders -= 1;
        }
    }
}

impl<K, P> Drop for EndOfRound<'_, K, P> {
    fn drop(&mut self) {
        self.end();
    }
}

impl<K: Clone + PartialEq, P> Coalescer<K, P> {
    /// Evaluate `points` of `key`: `send` dispatches groups of points (each of one key) and
    /// answers each point in order; it is called on this thread with this caller's points
    /// and others', or not at all when another caller's round takes them along.
    ///
    /// `room`: whether a round sent now would find capacity idle (see
    /// [`crate::evaluator::Evaluator::has_room`]). A round starts at once when none travels;
    /// a second one only when there is room for it, else this caller's points wait for the
    /// next round, which then takes more points in one dispatch. A round travels until
    /// `send` says it has arrived ([`Arrival`]) or returns.
    pub fn evaluate<S>(
        &self,
        key: K,
        points: Vec<P>,
        room: bool,
        send: S,
    ) -> Result<Vec<Evaluation>, Fault>
    where
        S: Fn(Groups<K, P>, &Arrival) -> Answers,
    {
        let reply = Arc::new(Reply::new());
        let mut queue = self.queue.lock().expect("coalescer lock");
        let lead = queue.leaders == 0 || (room && queue.leaders < LEADERS);
        if lead {
            queue.leaders += 1;
        }
        queue.waiting.push(Ask {
            key,
            points,
            reply: reply.clone(),
            leads: lead,
        });
        drop(queue);
        if !lead {
            if let Some(answer) = reply.wait() {
                return answer;
            }
        }
        // This caller leads a round: everything waiting (its own points among them, unless
        // a round begun since took them along).
        let round = std::mem::take(&mut self.queue.lock().expect("coalescer lock").waiting);
        {
            let end = EndOfRound {
                coalescer: self,
                ended: Cell::new(false),
            };
            self.send_round(round, &send, &Arrival(&|| end.arrive()));
        }
        loop {
            if let Some(answer) = reply.wait() {
                return answer;
            }
        }
    }

    /// Callers waiting for a round (not yet handed the baton).
    #[cfg(test)]
    pub(crate) fn waiting(&self) -> usize {
        let queue = self.queue.lock().expect("coalescer lock");
        queue.waiting.iter().filter(|ask| !ask.leads).count()
    }

    /// Dispatch one round: its asks grouped by key, each group as one batch; then every
    /// ask's share of its group's answers.
    fn send_round<S>(&self, round: Vec<Ask<K, P>>, send: &S, arrival: &Arrival)
    where
        S: Fn(Groups<K, P>, &Arrival) -> Answers,
    {
        if round.is_empty() {
            return;
        }
        let _unanswered = Unanswered(round.iter().map(|ask| ask.reply.clone()).collect());
        // Groups of asks by key, in order of first appearance.
        let mut groups: Vec<(K, Vec<usize>)> = Vec::new();
        for (i, ask) in round.iter().enumerate() {
            match groups.iter_mut().find(|(k, _)| *k == ask.key) {
                Some((_, members)) => members.push(i),
                None => groups.push((ask.key.clone(), vec![i])),
            }
        }
        let mut round: Vec<Option<Ask<K, P>>> = round.into_iter().map(Some).collect();
        let mut sizes: Vec<Vec<usize>> = Vec::with_capacity(groups.len());
        let batches: Groups<K, P> = groups
            .iter()
            .map(|(key, members)| {
                let mut points = Vec::new();
                let mut counts = Vec::with_capacity(members.len());
                for &i in members {
                    let ask = round[i].as_mut().expect("each ask in one group");
                    counts.push(ask.points.len());
                    points.append(&mut ask.points);
                }
                sizes.push(counts);
                (key.clone(), points)
            })
            .collect();
        tracing::trace!(
            asks = round.len(),
            points = batches.iter().map(|(_, p)| p.len()).sum::<usize>(),
            "round"
        );
        let answers = send(batches, arrival);
        for (((_, members), counts), answer) in groups.iter().zip(&sizes).zip(answers) {
            match answer {
                Ok(evaluations) => {
                    let mut evaluations = evaluations.into_iter();
                    for (&i, &n) in members.iter().zip(counts) {
                        let share: Vec<Evaluation> = evaluations.by_ref().take(n).collect();
                        let ask = round[i].take().expect("answered once");
                        ask.reply.answer(Ok(share));
                    }
                }
                Err(fault) => {
                    for &i in members {
                        let ask = round[i].take().expect("answered once");
                        ask.reply.answer(Err(fault.clone()));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    fn evaluation(x: f64) -> Evaluation {
        Evaluation {
            objective: x,
            sse: vec![x],
            failure: None,
            residuals: Vec::new(),
        }
    }

    /// A dispatch that answers each point with its first coordinate, slowly, counting calls.
    fn slow_send<'a>(
        calls: &'a AtomicUsize,
        largest: &'a AtomicUsize,
    ) -> impl Fn(Groups<u8>, &Arrival) -> Answers + 'a {
        move |groups, _| {
            calls.fetch_add(1, Ordering::SeqCst);
            std::thread::sleep(Duration::from_millis(20));
            groups
                .into_iter()
                .map(|(_, points)| {
                    largest.fetch_max(points.len(), Ordering::SeqCst);
                    Ok(points.iter().map(|p| evaluation(p[0])).collect())
                })
                .collect()
        }
    }

    #[test]
    fn a_lone_caller_is_sent_at_once_and_answered_in_order() {
        let coalescer = Coalescer::<u8>::default();
        let (calls, largest) = (AtomicUsize::new(0), AtomicUsize::new(0));
        let answer = coalescer
            .evaluate(
                0,
                vec![vec![1.0], vec![2.0]],
                true,
                slow_send(&calls, &largest),
            )
            .unwrap();
        assert_eq!(answer, vec![evaluation(1.0), evaluation(2.0)]);
        assert_eq!(calls.load(Ordering::SeqCst), 1);
    }

    #[test]
    fn many_callers_share_dispatches_and_each_gets_its_own_answers() {
        let coalescer = Coalescer::<u8>::default();
        let (calls, largest) = (AtomicUsize::new(0), AtomicUsize::new(0));
        let callers = 12;
        let rounds = 10;
        std::thread::scope(|scope| {
            for c in 0..callers {
                let (coalescer, calls, largest) = (&coalescer, &calls, &largest);
                scope.spawn(move || {
                    for r in 0..rounds {
                        let x = (100 * c + r) as f64;
                        let answer = coalescer
                            .evaluate(
                                0,
                                vec![vec![x], vec![x + 0.5]],
                                true,
                                slow_send(calls, largest),
                            )
                            .unwrap();
                        assert_eq!(answer, vec![evaluation(x), evaluation(x + 0.5)]);
                    }
                });
            }
        });
        let calls = calls.load(Ordering::SeqCst);
        assert!(
            calls < callers * rounds / 2,
            "{calls} dispatches for {} asks",
            callers * rounds
        );
        assert!(largest.load(Ordering::SeqCst) > 2, "asks were grouped");
    }

    #[test]
    fn without_room_a_second_round_waits_and_takes_more_points() {
        for room in [true, false] {
            let coalescer = Coalescer::<u8>::default();
            let (travelling, most) = (AtomicUsize::new(0), AtomicUsize::new(0));
            let (calls, largest) = (AtomicUsize::new(0), AtomicUsize::new(0));
            let send = |groups: Groups<u8>, arrival: &Arrival| {
                let now = travelling.fetch_add(1, Ordering::SeqCst) + 1;
                most.fetch_max(now, Ordering::SeqCst);
                let answers = slow_send(&calls, &largest)(groups, arrival);
                travelling.fetch_sub(1, Ordering::SeqCst);
                answers
            };
            std::thread::scope(|scope| {
                for c in 0..8 {
                    let (coalescer, send) = (&coalescer, &send);
                    scope.spawn(move || {
                        for r in 0..5 {
                            let x = f64::from(10 * c + r);
                            let answer = coalescer.evaluate(0, vec![vec![x]], room, send).unwrap();
                            assert_eq!(answer, vec![evaluation(x)]);
                        }
                    });
                }
            });
            let most = most.load(Ordering::SeqCst);
            if room {
                assert!(most <= LEADERS, "{most} rounds at once");
            } else {
                assert_eq!(most, 1, "a second round went without room");
            }
        }
    }

    #[test]
    fn an_arrived_round_lets_the_next_set_out_while_it_settles() {
        // Without room a second round waits for the first; the first says it has arrived
        // and then settles until the second has been sent (or 10 s have passed).
        let coalescer = Coalescer::<u8>::default();
        let second_sent = (Mutex::new(false), Condvar::new());
        let first_travels = (Mutex::new(false), Condvar::new());
        let set_out_while_settling = AtomicUsize::new(0);
        let answer = |groups: Groups<u8>| -> Answers {
            groups
                .into_iter()
                .map(|(_, p)| Ok(p.iter().map(|p| evaluation(p[0])).collect()))
                .collect()
        };
        std::thread::scope(|scope| {
            scope.spawn(|| {
                let send = |groups: Groups<u8>, arrival: &Arrival| {
                    *first_travels.0.lock().unwrap() = true;
                    first_travels.1.notify_all();
                    // Let the second caller queue behind this round.
                    let queued = std::time::Instant::now() + Duration::from_secs(10);
                    while coalescer.waiting() == 0 && std::time::Instant::now() < queued {
                        std::thread::sleep(Duration::from_millis(1));
                    }
                    arrival.arrived();
                    let sent = second_sent.0.lock().unwrap();
                    let (sent, _) = second_sent
                        .1
                        .wait_timeout_while(sent, Duration::from_secs(10), |sent| !*sent)
                        .unwrap();
                    if *sent {
                        set_out_while_settling.fetch_add(1, Ordering::SeqCst);
                    }
                    answer(groups)
                };
                let got = coalescer.evaluate(0, vec![vec![1.0]], false, send).unwrap();
                assert_eq!(got, vec![evaluation(1.0)]);
            });
            scope.spawn(|| {
                let travels = first_travels.0.lock().unwrap();
                drop(first_travels.1.wait_while(travels, |t| !*t).unwrap());
                let send = |groups: Groups<u8>, _: &Arrival| {
                    *second_sent.0.lock().unwrap() = true;
                    second_sent.1.notify_all();
                    answer(groups)
                };
                let got = coalescer.evaluate(0, vec![vec![2.0]], false, send).unwrap();
                assert_eq!(got, vec![evaluation(2.0)]);
            });
        });
        assert_eq!(set_out_while_settling.load(Ordering::SeqCst), 1);
    }

    #[test]
    fn points_of_different_keys_go_in_separate_groups() {
        let coalescer = Coalescer::<u8>::default();
        let mixed = AtomicUsize::new(0);
        let send = |groups: Vec<(u8, Vec<Vec<f64>>)>, _: &Arrival| {
            std::thread::sleep(Duration::from_millis(10));
            groups
                .into_iter()
                .map(|(key, points)| {
                    if points.iter().any(|p| p[1] as u8 != key) {
                        mixed.fetch_add(1, Ordering::SeqCst);
                    }
                    Ok(points.iter().map(|p| evaluation(p[0])).collect())
                })
                .collect()
        };
        std::thread::scope(|scope| {
            for c in 0..8u8 {
                let (coalescer, send) = (&coalescer, &send);
                scope.spawn(move || {
                    for r in 0..5 {
                        let x = f64::from(10 * c + r);
                        let key = c % 3;
                        let answer = coalescer
                            .evaluate(key, vec![vec![x, f64::from(key)]], true, send)
                            .unwrap();
                        assert_eq!(answer, vec![evaluation(x)]);
                    }
                });
            }
        });
        assert_eq!(mixed.load(Ordering::SeqCst), 0);
    }

    #[test]
    fn a_fault_reaches_every_caller_of_its_group_and_a_panic_answers_the_waiting() {
        let coalescer = Coalescer::<u8>::default();
        let fault = coalescer.evaluate(0, vec![vec![1.0]], true, |groups, _| {
            groups
                .into_iter()
                .map(|_| Err(Fault::unavailable("no worker")))
                .collect()
        });
        assert_eq!(fault.unwrap_err().message, "no worker");
        let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            coalescer.evaluate(0, vec![vec![1.0]], true, |_, _| panic!("dispatch broke"))
        }));
        assert!(panicked.is_err());
        // The leader's place was given back: the next caller dispatches.
        let answer = coalescer
            .evaluate(0, vec![vec![3.0]], true, |groups, _| {
                groups
                    .into_iter()
                    .map(|(_, p)| Ok(p.iter().map(|p| evaluation(p[0])).collect()))
                    .collect()
            })
            .unwrap();
        assert_eq!(answer, vec![evaluation(3.0)]);
    }
}
