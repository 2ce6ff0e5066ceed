//! The pair pass and the grain pass of a step in one sweep over the grain chunks: a chunk's
//! pairs (those whose first grain is one of its grains), then at once its grains, while the
//! pairs' records and the grains' frames are still in cache (issue #16: at 10⁵ grains the two
//! passes one after the other read every record back from memory; the sweep was 1.05 times as
//! fast on the dense bench's full level, on one thread).
//!
//! A grain chunk needs the records of its grains' pairs: its own chunk's (the pairs `[g, j]`)
//! and those of the pairs `[i, g]`, whose first grain i comes before g (the list holds
//! `i < j`), in the same chunk or an earlier one. One task sweeps a run of consecutive chunks
//! in order, so that the chunk's own pairs and those of the task's earlier chunks are done
//! when its grains are; a chunk with a pair `[i, g]` whose first grain lies before the task's
//! run waits ([`earliest_first_grains`] says which) until every earlier run has ended and its
//! own run's task is past it: then the task that ends the last of these takes its grains. The
//! same chunks wait for the frames, too: the pair pass of an earlier run reads the frames of
//! its pairs' second grains, which the grain pass replaces by the next step's, and those
//! grains are exactly the grains of the chunks that wait. Where too many chunks would wait,
//! the sweep is the pair pass and then the grain pass, in a second parallel round.
//!
//! Each chunk's results are the same whatever task computes it, and its sums go to its own
//! slot, added in chunk order after the sweep: the step's bits do not depend on the number of
//! tasks or threads.

use super::grain_pass::{GrainChunk, GrainPass};
use super::pairs::PairPass;
use super::{
    ChunkSums, Frame, GRAIN_CHUNK, GrainStress, MAX_WALLS, PairContact, PairState, PairSums,
    prefetch_address,
};
use crate::geometry::broadphase::NeighborList;
use crate::grain::{Grain, GrainLevel};
use glam::DVec2;
use rayon::prelude::*;
use std::marker::PhantomData;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

/// Rows of a table that the tasks of a sweep read while other tasks write other rows of it
/// (the frames, the pairs' flags and records): a slice's reference would claim the whole
/// table for as long as it lives. Built from a slice, it is one; built from a raw pointer
/// ([`SharedRows::from_raw`]), its maker answers for each row's reads and writes being
/// ordered.
pub(super) struct SharedRows<'a, T> {
    start: *const T,
    len: usize,
    rows: PhantomData<&'a [T]>,
}

impl<T> Clone for SharedRows<'_, T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for SharedRows<'_, T> {}

// SAFETY: the view hands out shared references to its rows only, as `&[T]` does.
unsafe impl<T: Sync> Send for SharedRows<'_, T> {}
// SAFETY: as above.
unsafe impl<T: Sync> Sync for SharedRows<'_, T> {}

impl<'a, T> SharedRows<'a, T> {
    #[cfg(test)]
    pub fn new(rows: &'a [T]) -> Self {
        Self {
            start: rows.as_ptr(),
            len: rows.len(),
            rows: PhantomData,
        }
    }

    /// # Safety
    /// `start` points to `len` initialised rows that stay allocated for `'a`, and no row is
    /// written while a reference this view gave to it is alive, nor read through the view
    /// while something else writes it.
    pub unsafe fn from_raw(start: *const T, len: usize) -> Self {
        Self {
            start,
            len,
            rows: PhantomData,
        }
    }

    #[inline(always)]
    pub fn len(self) -> usize {
        self.len
    }

    /// Row `k`; panics past the end, as a slice's index does.
    #[inline(always)]
    pub fn row(self, k: usize) -> &'a T {
        assert!(k < self.len);
        // SAFETY: k is a row of the view (checked above).
        unsafe { &*self.start.add(k) }
    }

    /// # Safety
    /// `k` is below [`len`](Self::len).
    #[inline(always)]
    pub unsafe fn row_unchecked(self, k: usize) -> &'a T {
        debug_assert!(k < self.len);
        // SAFETY: the caller's.
        unsafe { &*self.start.add(k) }
    }

    /// The rows `range`; panics unless they are rows of the view.
    #[inline(always)]
    pub fn rows(self, range: Range<usize>) -> &'a [T] {
        assert!(range.start <= range.end && range.end <= self.len);
        // SAFETY: the range lies within the view (checked above).
        unsafe { std::slice::from_raw_parts(self.start.add(range.start), range.len()) }
    }
}

/// A table whose disjoint runs of rows the sweep's tasks write, one task a run at a time
/// ([`RowRuns::run`]).
struct RowRuns<'a, T> {
    start: *mut T,
    len: usize,
    rows: PhantomData<&'a mut [T]>,
}

// SAFETY: the runs it hands out are `&mut [T]`, which may be sent to another thread when T is
// `Send`; that they are disjoint is the caller's to keep (`RowRuns::run`).
unsafe impl<T: Send> Send for RowRuns<'_, T> {}
// SAFETY: as above.
unsafe impl<T: Send> Sync for RowRuns<'_, T> {}

impl<'a, T> RowRuns<'a, T> {
    fn new(rows: &'a mut [T]) -> Self {
        Self {
            start: rows.as_mut_ptr(),
            len: rows.len(),
            rows: PhantomData,
        }
    }

    /// The rows `range` (clipped to the table), to write.
    ///
    /// # Safety
    /// No other reference to these rows is alive while the run is, nor made until it ends.
    #[inline(always)]
    #[allow(clippy::mut_from_ref)]
    unsafe fn run(&self, range: Range<usize>) -> &'a mut [T] {
        let end = range.end.min(self.len);
        let start = range.start.min(end);
        // SAFETY: the rows lie within the table (clipped above); the caller's for the rest.
        unsafe { std::slice::from_raw_parts_mut(self.start.add(start), end - start) }
    }
}

/// The rows of a world that the sweep writes: each grain chunk's rows and each chunk's pairs.
pub(super) struct SweepRows<'a> {
    /// Every grain's rows.
    pub grains: GrainChunk<'a>,
    pub pair_states: &'a mut [PairState],
    pub pair_lengths: &'a mut [f64],
    pub pair_active: &'a mut [bool],
    pub pair_contacts: &'a mut [PairContact],
    /// Where each grain chunk's pairs end (see [`super::pair_chunk_ends`]).
    pub pair_chunk_ends: &'a [usize],
    /// The least first grain of each grain chunk's pairs ([`earliest_first_grains`]).
    pub earliest_first_grains: &'a [u32],
    /// How the tasks share the chunks: made with `earliest_first_grains` for the pool's
    /// threads ([`SweepPlan::refresh`]).
    pub plan: &'a SweepPlan,
}

/// What the sweep reads while it writes the rows (built from their views: the frames for the
/// pair pass, the pairs' flags and records for the grain pass).
pub(super) struct SweepViews<'a> {
    pub frames: SharedRows<'a, Frame>,
    pub pair_active: SharedRows<'a, bool>,
    pub pair_contacts: SharedRows<'a, PairContact>,
}

/// One grain chunk's results: its pairs' sums, its grains' (`None` until its grains are
/// done), and the seconds each pass took on it.
#[derive(Default)]
struct ChunkResults {
    pairs: PairSums,
    grains: Option<ChunkSums>,
    pair_seconds: f64,
    grain_seconds: f64,
}

/// What a sweep leaves: each chunk's results, in chunk order, and the share of its time the
/// pair pass took.
pub(super) struct SweepResults {
    chunks: Vec<ChunkResults>,
    pub pair_share: f64,
    /// Whether the grains followed their pairs (see [`SweepPlan::fused`]), and how many
    /// chunks waited.
    pub fused: bool,
    pub waiting: usize,
    /// The runs the threads took.
    pub runs: usize,
    /// The seconds the sweep's tasks spent on chunks, summed, and the sweep's wall-clock
    /// seconds times its threads: their ratio is how busy the threads were.
    pub busy_seconds: f64,
    pub thread_seconds: f64,
}

impl SweepResults {
    /// Each chunk's pair sums, in chunk order.
    pub fn pair_sums(&self) -> impl Iterator<Item = &PairSums> {
        self.chunks.iter().map(|chunk| &chunk.pairs)
    }

    /// Each chunk's grain sums, in chunk order: every chunk's, unless a pair failed.
    pub fn grain_sums(&self) -> impl Iterator<Item = &ChunkSums> + Clone {
        self.chunks.iter().filter_map(|chunk| chunk.grains.as_ref())
    }
}

/// The pair pass and the grain pass over every chunk (see the module's docs): `passes` makes
/// the two passes from the views of the rows being written. The sweep stops short of a
/// chunk's grains (and of those of the later chunks of its run) when a pair of its run
/// failed: its results then hold the failure, and some grains are updated, others not.
pub(super) fn sweep<'a>(
    rows: SweepRows<'a>,
    passes: impl FnOnce(SweepViews<'a>) -> (PairPass<'a>, GrainPass<'a>),
) -> SweepResults {
    let chunks = rows.pair_chunk_ends.len();
    let GrainChunk {
        grains,
        stresses,
        levels,
        wall_histories,
        frames,
        directions,
        centers,
        reach,
        wraps,
    } = rows.grains;
    let grain_count = grains.len();
    assert!(
        chunks == grain_count.div_ceil(GRAIN_CHUNK)
            && rows.earliest_first_grains.len() == chunks
            && [
                stresses.len(),
                levels.len(),
                wall_histories.len(),
                frames.len(),
                directions.len(),
                centers.len(),
                reach.len(),
                wraps.len()
            ]
            .iter()
            .all(|&len| len == grain_count)
            && rows.pair_states.len() == rows.pair_active.len()
            && rows.pair_lengths.len() == rows.pair_active.len()
            && rows.pair_active.len() == rows.pair_contacts.len()
            && rows
                .pair_chunk_ends
                .last()
                .is_none_or(|&end| end == rows.pair_contacts.len())
            && rows.pair_chunk_ends.is_sorted(),
        "the sweep's rows disagree with the chunks of the list"
    );
    let frames = RowRuns::new(frames);
    let pair_active = RowRuns::new(rows.pair_active);
    let pair_contacts = RowRuns::new(rows.pair_contacts);
    // SAFETY: the views and the runs cover the same rows; the order of the sweep (the module's
    // docs) writes a row only where no view reads it: a chunk's frames after every pair that
    // reads them, a pair's flag and record before any grain that reads them.
    let views = unsafe {
        SweepViews {
            frames: SharedRows::from_raw(frames.start, frames.len),
            pair_active: SharedRows::from_raw(pair_active.start, pair_active.len),
            pair_contacts: SharedRows::from_raw(pair_contacts.start, pair_contacts.len),
        }
    };
    let (pair_pass, grain_pass) = passes(views);
    let writes = Writes {
        grains: RowRuns::new(grains),
        stresses: RowRuns::new(stresses),
        levels: RowRuns::new(levels),
        wall_histories: RowRuns::new(wall_histories),
        frames,
        directions: RowRuns::new(directions),
        centers: RowRuns::new(centers),
        reach: RowRuns::new(reach),
        wraps: RowRuns::new(wraps),
        pair_states: RowRuns::new(rows.pair_states),
        pair_lengths: RowRuns::new(rows.pair_lengths),
        pair_active,
        pair_contacts,
        pair_chunk_ends: rows.pair_chunk_ends,
    };
    let mut results: Vec<ChunkResults> = (0..chunks).map(|_| ChunkResults::default()).collect();
    let plan = rows.plan;
    assert!(
        plan.chunks == chunks && plan.threads == rayon::current_num_threads(),
        "the sweep's plan is for {} chunks on {} threads, not {chunks} on {}",
        plan.chunks,
        plan.threads,
        rayon::current_num_threads()
    );
    let runs = plan.runs();
    let run_chunks = |r: usize| plan.run_chunks(r);
    let efg = rows.earliest_first_grains;
    let waiting_in = |r: usize, chunk: usize| waits_from(efg, chunk, plan.starts[r]);
    let waiting_chunks = &plan.waiting_chunks;
    let waiting_of = |r: usize| {
        let run = run_chunks(r);
        &waiting_chunks[waiting_chunks.partition_point(|&c| c < run.start)
            ..waiting_chunks.partition_point(|&c| c < run.end)]
    };
    // What run r's waiting grains still wait for: the end of each earlier run (whose pairs
    // read their frames and write the records they read), and its own task's pairs up to
    // its last waiting chunk. Once the counter is down (its acquire orders the grains' reads
    // after every write they wait for) the tasks take them chunk by chunk: the one that
    // ended the last of these, and any task whose run is over while another's still runs.
    // So the pool needs no second round: on two threads, on LAMMPS's 10⁵ packing, that
    // round took 0.11 ms a step for six chunks' grains (issue #16).
    let states: Vec<RunState> = (0..runs).map(RunState::new).collect();
    let any_failed = AtomicBool::new(false);
    let sweep_start = Instant::now();
    let results_rows = RowRuns::new(&mut results);
    // SAFETY (for each `result` below): a chunk's results are written by its run's task (its
    // pairs, and its grains unless they wait) and, for a waiting chunk, by the one task that
    // claims it after the counter says that run's task is past it.
    let result_of = |chunk: usize| unsafe { &mut results_rows.run(chunk..chunk + 1)[0] };
    // Takes the grains of one waiting chunk whose run's counter is down, if one is left.
    let take_waiting = || -> bool {
        for (r, state) in states.iter().enumerate() {
            if state.pending.load(Ordering::Acquire) != 0 || any_failed.load(Ordering::Acquire) {
                continue;
            }
            let Some(&chunk) =
                waiting_of(r).get(state.next_waiting.fetch_add(1, Ordering::Relaxed))
            else {
                continue;
            };
            let start = Instant::now();
            // SAFETY: every pair that reads the chunk's frames, and every pair its grains
            // read, is done: those of the earlier runs (ended) and its own run's up to its
            // last waiting chunk (later chunks' pairs meet only later grains); the counter
            // hands each chunk to one task.
            let grains = unsafe { writes.grain_chunk(&grain_pass, chunk) };
            let result = result_of(chunk);
            result.grains = Some(grains);
            result.grain_seconds = start.elapsed().as_secs_f64();
            return true;
        }
        false
    };
    let one_wait_done = |r: usize| {
        if states[r].pending.fetch_sub(1, Ordering::AcqRel) == 1 {
            while take_waiting() {}
        }
    };
    let sweep_run = |r: usize| {
        states[r].started.store(true, Ordering::Release);
        let mut failed = false;
        let last_waiting = waiting_of(r).last().copied();
        for chunk in run_chunks(r) {
            let start = Instant::now();
            // SAFETY: each chunk's pairs are swept once, by its run's task.
            let pairs = unsafe { writes.pair_chunk(&pair_pass, chunk) };
            let pairs_done = Instant::now();
            failed |= pairs.failure.is_some();
            let result = result_of(chunk);
            result.pairs = pairs;
            result.pair_seconds = (pairs_done - start).as_secs_f64();
            if failed {
                any_failed.store(true, Ordering::Release);
            }
            if last_waiting == Some(chunk) {
                one_wait_done(r);
            }
            if plan.fused && !failed && !waiting_in(r, chunk) {
                // SAFETY: the chunk's pairs and those of its run's earlier chunks are done, and
                // no pair of it meets a grain before the run: the records it reads are
                // written, and the pair passes still to come read none of its frames.
                let grains = unsafe { writes.grain_chunk(&grain_pass, chunk) };
                let result = result_of(chunk);
                result.grains = Some(grains);
                result.grain_seconds = pairs_done.elapsed().as_secs_f64();
            }
        }
        for later in r + 1..runs {
            if !waiting_of(later).is_empty() {
                one_wait_done(later);
            }
        }
        states[r].ended.store(true, Ordering::Release);
    };
    // The tasks take the runs in order, each the next one left as it ends one: a thread that
    // runs slower (a core shared with another program) takes fewer of them (issue #16: with
    // one run a thread, the threads were busy 93% of the sweep of the 10⁵ run on the Intel
    // machine, whose two cores ran at unequal speeds).
    let next_run = AtomicUsize::new(0);
    (0..plan.threads.min(runs)).into_par_iter().for_each(|_| {
        loop {
            let r = next_run.fetch_add(1, Ordering::Relaxed);
            if r >= runs {
                break;
            }
            sweep_run(r);
        }
        // Help with the waiting grains while another task still runs (it waits on nothing,
        // so this ends); a run taken but not yet started is left to the task that took it,
        // which then ends the last of its waits itself.
        let mut spins = 0u32;
        loop {
            if take_waiting() {
                continue;
            }
            let running = states.iter().any(|state| {
                state.started.load(Ordering::Acquire) && !state.ended.load(Ordering::Acquire)
            });
            if !running || any_failed.load(Ordering::Acquire) {
                break;
            }
            spins += 1;
            if spins.is_multiple_of(64) {
                std::thread::yield_now();
            } else {
                std::hint::spin_loop();
            }
        }
    });
    let failed = results.iter().any(|result| result.pairs.failure.is_some());
    if !failed && results.iter().any(|result| result.grains.is_none()) {
        // The passes one after the other: every pair is done, and no pair pass reads a frame
        // any more.
        results
            .par_iter_mut()
            .enumerate()
            .filter(|(_, result)| result.grains.is_none())
            .for_each(|(chunk, result)| {
                let start = Instant::now();
                // SAFETY: each waiting chunk is swept once, after every pair.
                result.grains = Some(unsafe { writes.grain_chunk(&grain_pass, chunk) });
                result.grain_seconds = start.elapsed().as_secs_f64();
            });
    }
    let (pair_seconds, grain_seconds) = results.iter().fold((0.0, 0.0), |(p, g), result| {
        (p + result.pair_seconds, g + result.grain_seconds)
    });
    SweepResults {
        chunks: results,
        pair_share: pair_seconds / (pair_seconds + grain_seconds).max(f64::MIN_POSITIVE),
        fused: plan.fused,
        waiting: plan.waiting,
        runs,
        busy_seconds: pair_seconds + grain_seconds,
        thread_seconds: sweep_start.elapsed().as_secs_f64() * rayon::current_num_threads() as f64,
    }
}

/// Where one run of the sweep is, for its waiting chunks (see [`sweep`]).
struct RunState {
    /// What the run's waiting grains still wait for: the end of each earlier run, and its own
    /// task's pairs up to its last waiting chunk.
    pending: AtomicUsize,
    /// The next of its waiting chunks to hand out once `pending` is down.
    next_waiting: AtomicUsize,
    started: AtomicBool,
    ended: AtomicBool,
}

impl RunState {
    /// Run `r`'s state before the sweep: it waits on the `r` runs before it and on itself.
    fn new(r: usize) -> Self {
        Self {
            pending: AtomicUsize::new(r + 1),
            next_waiting: AtomicUsize::new(0),
            started: AtomicBool::new(false),
            ended: AtomicBool::new(false),
        }
    }
}

/// How the sweep would take grains numbered as `neighbors`' list numbers them on `threads`
/// threads: the plan a step of those grains would follow. For a check of a sample's numbering
/// before a run (`sample::order::threads_wait_warning`).
pub fn sweep_plan_of(neighbors: &NeighborList, grains: usize, threads: usize) -> SweepPlan {
    SweepPlan::new(&earliest_first_grains(neighbors, grains), threads)
}

/// The sweeps of a run so far ([`World::sweep_tally`](super::World)): how many, how many took
/// the two passes one after the other, and their waiting chunks, summed; and the threads' time
/// in them, busy and in all (a timing, unlike the counts).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SweepTally {
    pub sweeps: u64,
    pub two_passes: u64,
    pub waiting_chunks: u64,
    /// The chunks of the last sweep, and the runs its threads took.
    pub chunks: usize,
    pub runs: usize,
    pub busy_seconds: f64,
    pub thread_seconds: f64,
}

impl SweepTally {
    pub(super) fn add(&mut self, swept: &SweepResults) {
        self.sweeps += 1;
        self.two_passes += u64::from(!swept.fused);
        self.waiting_chunks += swept.waiting as u64;
        self.chunks = swept.chunks.len();
        self.runs = swept.runs;
        self.busy_seconds += swept.busy_seconds;
        self.thread_seconds += swept.thread_seconds;
    }

    /// The share of the threads' time in the sweeps that they spent on chunks (the rest:
    /// waiting for each other, and the pool's plumbing); 0 without a sweep.
    pub fn busy_share(&self) -> f64 {
        self.busy_seconds / self.thread_seconds.max(f64::MIN_POSITIVE)
    }

    /// The chunks that waited, on average over the sweeps (0 without a sweep).
    pub fn mean_waiting_chunks(&self) -> f64 {
        self.waiting_chunks as f64 / self.sweeps.max(1) as f64
    }

    /// The sweeps since `before`, a tally of the same run taken earlier.
    pub fn since(&self, before: &SweepTally) -> SweepTally {
        SweepTally {
            sweeps: self.sweeps - before.sweeps,
            two_passes: self.two_passes - before.two_passes,
            waiting_chunks: self.waiting_chunks - before.waiting_chunks,
            chunks: self.chunks,
            runs: self.runs,
            busy_seconds: self.busy_seconds - before.busy_seconds,
            thread_seconds: self.thread_seconds - before.thread_seconds,
        }
    }
}

/// "300 sweeps, 0 in two passes; 6.0 of 391 chunks waited (mean), 2 runs; threads busy 97.1%".
impl std::fmt::Display for SweepTally {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} sweeps, {} in two passes; {:.1} of {} chunks waited (mean), {} runs; threads \
             busy {:.1}%",
            self.sweeps,
            self.two_passes,
            self.mean_waiting_chunks(),
            self.chunks,
            self.runs,
            100.0 * self.busy_share()
        )
    }
}

/// How the sweep's tasks share the chunks.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SweepPlan {
    /// Where each task's run of chunks starts, and the chunks' end: run `r` is
    /// `starts[r]..starts[r + 1]`: one run a thread, or runs that shrink towards the sweep's
    /// end, which the threads take in order as they come free. On one thread, one run: it
    /// sweeps every chunk at once.
    starts: Vec<usize>,
    /// The chunks whose grains wait, in order, where the passes are fused (else none).
    waiting_chunks: Vec<usize>,
    /// The threads it is made for.
    threads: usize,
    pub chunks: usize,
    /// The chunks whose grains would wait, with the passes fused (see
    /// [`SweepPlan::waits`]; on one thread, none): what decides `fused`.
    pub waiting: usize,
    /// Whether a run's grains follow its pairs (but those of the chunks that wait); else every
    /// grain waits for the second round, and the sweep is the pair pass and then the grain
    /// pass.
    pub fused: bool,
}

impl SweepPlan {
    pub(super) fn new(earliest_first_grains: &[u32], threads: usize) -> Self {
        let even = Self::even(earliest_first_grains, threads);
        let chunks = earliest_first_grains.len();
        if threads <= 1 {
            return even;
        }
        if !even.fused {
            // Every grain waits for the second round: the runs are the pair pass's alone, and
            // shrinking ones, down to one chunk, make no chunk wait longer (issue #16: on
            // LAMMPS's packing in its file's order, two threads on the Intel machine, one run
            // a thread kept them busy 85% of the sweep).
            let starts = guided_starts(chunks, threads, 1);
            return Self::with_starts(earliest_first_grains, threads, starts, None);
        }
        if chunks < 4 * (threads + 1) * GUIDED_MIN_RUN {
            return even;
        }
        // Runs that shrink towards the sweep's end, which the threads take as they come free,
        // where few enough chunks wait: each run's start is a front that the chunks after it
        // wait on (two chunks on a lattice numbered row by row, some twenty on a sample along
        // a space-filling curve at 10⁵ grains). Their waiting grains are taken as soon as the
        // runs before them end, by whichever thread is free, so that more of them wait than
        // one run a thread lets wait (issue #16: 82 of 391 chunks on the 10⁵ run's gas, two
        // threads, busy 98.6% of the sweep against 95.2% with one run a thread).
        let guided = Self::guided(
            earliest_first_grains,
            threads,
            GUIDED_MIN_RUN,
            MOST_WAITING_GUIDED,
        );
        if guided.fused { guided } else { even }
    }

    /// Runs that shrink towards the sweep's end ([`guided_starts`]), fused unless more than
    /// one chunk in `most_waiting` waits.
    fn guided(
        earliest_first_grains: &[u32],
        threads: usize,
        min_run: usize,
        most_waiting: usize,
    ) -> Self {
        let starts = guided_starts(earliest_first_grains.len(), threads, min_run);
        Self::with_starts(earliest_first_grains, threads, starts, Some(most_waiting))
    }

    /// One run a thread, each the same work but for its waiting chunks.
    fn even(earliest_first_grains: &[u32], threads: usize) -> Self {
        let chunks = earliest_first_grains.len();
        let run = chunks.div_ceil(threads.max(1)).max(1);
        let even: Vec<usize> = (0..chunks.div_ceil(run))
            .map(|r| r * run)
            .chain([chunks])
            .collect();
        // A run's waiting grains are left to the end of the sweep, where every thread shares
        // them: a run with waiting chunks ends sooner by their grains, and with runs of equal
        // length its thread then idled until the first run ended (issue #16: 3.5% of the
        // threads' time in the sweep on LAMMPS's 10⁵ packing, two threads, six chunks
        // waiting). So each run is lengthened by half its waiting chunks, the grain pass's
        // rough share of a chunk's time (fixed, so that the plan is a function of the list).
        let waiting: Vec<usize> = (0..even.len() - 1)
            .map(|r| {
                (even[r]..even[r + 1])
                    .filter(|&c| waits_from(earliest_first_grains, c, even[r]))
                    .count()
            })
            .collect();
        let runs = waiting.len();
        let own_work = (chunks as f64 - 0.5 * waiting.iter().sum::<usize>() as f64) / runs as f64;
        let mut starts = Vec::with_capacity(runs + 1);
        let mut end = 0.0_f64;
        for &w in &waiting {
            starts.push((end.round() as usize).min(chunks));
            end += own_work + 0.5 * w as f64;
        }
        starts.push(chunks);
        Self::with_starts(earliest_first_grains, threads, starts, Some(MOST_WAITING))
    }

    /// The plan whose runs start at `starts` (and end at the chunks' end, `starts`' last),
    /// fused unless more than one chunk in `most_waiting` waits; never fused without it.
    fn with_starts(
        earliest_first_grains: &[u32],
        threads: usize,
        starts: Vec<usize>,
        most_waiting: Option<usize>,
    ) -> Self {
        let chunks = earliest_first_grains.len();
        let mut plan = Self {
            starts,
            waiting_chunks: Vec::new(),
            threads,
            chunks,
            waiting: 0,
            fused: false,
        };
        let waiting_chunks: Vec<usize> = (0..chunks)
            .filter(|&c| plan.waits(earliest_first_grains, c))
            .collect();
        plan.waiting = waiting_chunks.len();
        // The chunks that wait are the later runs' own: while their grains wait, the first
        // run's thread still computes its grains, and the others idle (on LAMMPS's packing,
        // in the order LAMMPS wrote it out, half the chunks waited and two threads stepped
        // 0.86 times as fast as with the two passes).
        plan.fused = most_waiting.is_some_and(|most| plan.waiting * most <= chunks);
        if plan.fused {
            plan.waiting_chunks = waiting_chunks;
        }
        plan
    }

    /// Makes the plan again where it is not one for the pool's threads and these chunks (the
    /// world keeps it from one step to the next, and drops it with each list build: making it
    /// each step allocated). The default plan is for no threads.
    pub(super) fn refresh(&mut self, earliest_first_grains: &[u32]) {
        let threads = rayon::current_num_threads();
        if self.threads != threads || self.chunks != earliest_first_grains.len() {
            *self = Self::new(earliest_first_grains, threads);
        }
    }

    /// The runs of chunks, one a task.
    fn runs(&self) -> usize {
        self.starts.len() - 1
    }

    /// The chunks of run `r`.
    fn run_chunks(&self, r: usize) -> Range<usize> {
        self.starts[r]..self.starts[r + 1]
    }

    /// Whether the grains of chunk `chunk` wait for the earlier runs: whether one of its pairs
    /// has its first grain before the chunk's run.
    fn waits(&self, earliest_first_grains: &[u32], chunk: usize) -> bool {
        let run = self.starts.partition_point(|&start| start <= chunk) - 1;
        waits_from(earliest_first_grains, chunk, self.starts[run])
    }
}

/// The sweep takes the two passes one after the other where more than one chunk in
/// `MOST_WAITING` would wait.
const MOST_WAITING: usize = 8;

/// The runs that shrink towards the sweep's end are taken where no more than one chunk in
/// `MOST_WAITING_GUIDED` waits, else one run a thread.
const MOST_WAITING_GUIDED: usize = 4;

/// The shortest of the runs that shrink towards the sweep's end, in chunks: fewer runs, fewer
/// fronts to wait on (issue #16: on the Intel machine, two threads, runs down to 4, 8 or 16
/// chunks kept the threads busy 97–99% of the sweep against 95–97% with one run a thread (the
/// medians of 5 or 6 runs each, on the bench's full lattice and on the 10⁵ run's gas); the
/// threads' time on the chunks moved by up to 8% from one sitting to the next, more than it
/// differed between them).
const GUIDED_MIN_RUN: usize = 8;

/// Runs that shrink towards the sweep's end, for `threads` threads: each takes a share
/// `1 / (threads + 1)` of the chunks left, but no fewer than `min_run` chunks, and the last
/// takes what is left where less than `min_run` chunks would follow it. The threads take the
/// first ones together, then each the next as it comes free: the last runs, short, even out
/// the threads' ends.
fn guided_starts(chunks: usize, threads: usize, min_run: usize) -> Vec<usize> {
    let mut starts = vec![0];
    let mut start = 0;
    while start < chunks {
        let left = chunks - start;
        let mut size = left.div_ceil(threads + 1).max(min_run).min(left);
        if left - size < min_run {
            size = left;
        }
        start += size;
        starts.push(start);
    }
    starts
}

/// Whether the grains of chunk `chunk`, in a run that starts at chunk `run_start`, wait for
/// the earlier runs: whether one of its pairs has its first grain before the run.
fn waits_from(earliest_first_grains: &[u32], chunk: usize, run_start: usize) -> bool {
    (earliest_first_grains[chunk] as usize) < run_start * GRAIN_CHUNK
}

/// The rows the sweep writes, as runs.
struct Writes<'a> {
    grains: RowRuns<'a, Grain>,
    stresses: RowRuns<'a, GrainStress>,
    levels: RowRuns<'a, GrainLevel>,
    wall_histories: RowRuns<'a, [f64; MAX_WALLS]>,
    frames: RowRuns<'a, Frame>,
    directions: RowRuns<'a, DVec2>,
    centers: RowRuns<'a, DVec2>,
    reach: RowRuns<'a, f64>,
    wraps: RowRuns<'a, [i64; 2]>,
    pair_states: RowRuns<'a, PairState>,
    pair_lengths: RowRuns<'a, f64>,
    pair_active: RowRuns<'a, bool>,
    pair_contacts: RowRuns<'a, PairContact>,
    pair_chunk_ends: &'a [usize],
}

impl Writes<'_> {
    /// # Safety
    /// Called once a sweep for each chunk, before any grain reads the chunk's pairs.
    unsafe fn pair_chunk(&self, pass: &PairPass<'_>, chunk: usize) -> PairSums {
        let start = if chunk == 0 {
            0
        } else {
            self.pair_chunk_ends[chunk - 1]
        };
        let pairs = start..self.pair_chunk_ends[chunk];
        self.prefetch_grain_rows(chunk);
        // SAFETY: the caller's: these runs of the pair rows are this chunk's alone.
        unsafe {
            pass.chunk(
                start,
                self.pair_states.run(pairs.clone()),
                self.pair_lengths.run(pairs.clone()),
                self.pair_active.run(pairs.clone()),
                self.pair_contacts.run(pairs),
            )
        }
    }

    /// Asks for the rows of chunk `chunk`'s grains that its grain pass reads or writes first,
    /// in a loop with nothing else to overlap their loads (its grains' levels, counted, and
    /// the broad phase's centres and reaches, copied from the new frames), while its pairs
    /// are swept (issue #16: the count of levels and the copy were 5.4% of a one-thread step
    /// on LAMMPS's 10⁵ packing, 3.4% with the rows asked for).
    #[inline(always)]
    fn prefetch_grain_rows(&self, chunk: usize) {
        fn lines<T>(rows: &RowRuns<'_, T>, chunk: usize) {
            let first = chunk * GRAIN_CHUNK;
            let count = GRAIN_CHUNK.min(rows.len.saturating_sub(first));
            let start = rows.start.wrapping_add(first).cast::<u8>().cast_const();
            for line in (0..count * size_of::<T>()).step_by(64) {
                prefetch_address(start.wrapping_add(line));
            }
        }
        lines(&self.levels, chunk);
        lines(&self.centers, chunk);
        lines(&self.reach, chunk);
    }

    /// # Safety
    /// Called once a sweep for each chunk, after every pair that reads its frames and every
    /// pair its grains read.
    unsafe fn grain_chunk(&self, pass: &GrainPass<'_>, chunk: usize) -> ChunkSums {
        let grains = chunk * GRAIN_CHUNK..(chunk + 1) * GRAIN_CHUNK;
        // SAFETY: the caller's: these runs of the grain rows are this chunk's alone.
        let rows = unsafe {
            GrainChunk {
                grains: self.grains.run(grains.clone()),
                stresses: self.stresses.run(grains.clone()),
                levels: self.levels.run(grains.clone()),
                wall_histories: self.wall_histories.run(grains.clone()),
                frames: self.frames.run(grains.clone()),
                directions: self.directions.run(grains.clone()),
                centers: self.centers.run(grains.clone()),
                reach: self.reach.run(grains.clone()),
                wraps: self.wraps.run(grains.clone()),
            }
        };
        pass.chunk(grains.start, rows)
    }
}

/// For each grain chunk, the least first grain of the pairs its grains are the second grain
/// of (the chunk's first grain where it has none): the sweep computes a chunk's grains in the
/// task that swept its pairs only when this grain is in the task's run.
pub(super) fn earliest_first_grains(neighbors: &NeighborList, grains: usize) -> Vec<u32> {
    (0..grains.div_ceil(GRAIN_CHUNK))
        .into_par_iter()
        .map(|chunk| {
            let members = chunk * GRAIN_CHUNK..grains.min((chunk + 1) * GRAIN_CHUNK);
            // A grain's second ends are in increasing pair order, and the list in increasing
            // first grain: its first second end has the least first grain.
            members
                .clone()
                .filter_map(|g| neighbors.second_ends_of(g).first())
                .map(|&p| neighbors.pairs[p as usize][0])
                .min()
                .unwrap_or(members.start as u32)
                .min(members.start as u32)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::boundary::periodic::PeriodicBoundary;
    use crate::grain::ModelLevel;
    use crate::integration::World;
    use crate::run::bench::{dense_packing, with_model};

    fn in_pool<T: Send>(threads: usize, work: impl FnOnce() -> T + Send) -> T {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(work)
    }

    /// A dense packing of about 2,600 grains (eleven chunks) at `level`, in its box or in a
    /// periodic cell of the box's size, the box squeezed.
    fn packing(level: ModelLevel, periodic: bool) -> World {
        let mut world = dense_packing(2600, 1.0);
        with_model(&mut world, level);
        if periodic {
            world = world.with_periodic(PeriodicBoundary::default());
        }
        let (w, h) = crate::boundary::walls::box_size(&world.walls);
        world.walls[crate::boundary::walls::RIGHT].velocity.x = -2e-3 * w;
        world.walls[crate::boundary::walls::TOP].velocity.y = -1e-3 * h;
        world
    }

    #[test]
    fn the_tally_counts_each_sweep_with_the_plan_the_sample_check_gives() {
        // Expectation: one sweep a step; on one thread no chunk waits and the passes are one
        // sweep; on three, the tally's last plan is what `sweep_plan_of` (the check of a
        // sample file's numbering) gives for the step's list, waiting chunks included, and
        // those are the chunks that `waits` names; the threads' busy share is a share.
        for threads in [1, 3] {
            let (tally, plan, waiting) = in_pool(threads, || {
                let mut world = packing(ModelLevel::Rigid, false);
                for _ in 0..5 {
                    world.step().unwrap();
                }
                let n = world.grains.len();
                let plan = sweep_plan_of(&world.neighbors, n, threads);
                let waiting = (0..world.earliest_first_grains.len())
                    .filter(|&c| plan.waits(&world.earliest_first_grains, c))
                    .count();
                (world.sweep_tally, plan, waiting)
            });
            assert_eq!(
                (tally.sweeps, tally.chunks),
                (5, plan.chunks),
                "{threads} threads"
            );
            assert_eq!(plan.waiting, waiting, "{threads} threads");
            // Each task's chunks take disjoint stretches of the sweep's wall time, so the
            // threads were busy for a share in (0, 1] of it.
            let busy = tally.busy_share();
            assert!(busy > 0.0 && busy <= 1.0, "{threads} threads: {tally:?}");
            if threads == 1 {
                assert_eq!((tally.two_passes, tally.waiting_chunks), (0, 0));
            } else {
                assert!(plan.waiting > 0, "{plan:?}");
                assert!(
                    tally.waiting_chunks >= plan.waiting as u64,
                    "{tally:?} {plan:?}"
                );
                assert!(
                    tally.two_passes >= u64::from(!plan.fused),
                    "{tally:?} {plan:?}"
                );
            }
        }
    }

    #[test]
    fn runs_with_waiting_chunks_are_longer_by_half_of_them() {
        // Expectation: the runs cover the chunks in order, one a thread; a run's waiting
        // grains are shared at the end of the sweep, so each run's own work (its chunks less
        // half its waiting ones, the grain pass's share) is the even share but for the
        // rounding of the run's two ends to whole chunks (half a chunk each) and a waiting
        // chunk gained or lost as its start moved (half a chunk): 1.5 chunks at most.
        for threads in [2, 3, 4] {
            let mut world = packing(ModelLevel::Rigid, false);
            world.step().unwrap();
            let efg = &world.earliest_first_grains;
            let plan = SweepPlan::even(efg, threads);
            let chunks = efg.len();
            assert_eq!(plan.runs(), threads);
            assert_eq!((plan.starts[0], plan.starts[threads]), (0, chunks));
            assert!(plan.starts.is_sorted(), "{plan:?}");
            let waiting: Vec<usize> = (0..threads)
                .map(|r| plan.run_chunks(r).filter(|&c| plan.waits(efg, c)).count())
                .collect();
            assert_eq!(waiting.iter().sum::<usize>(), plan.waiting);
            assert!(waiting[1..].iter().all(|&w| w > 0), "{waiting:?}");
            let even = (chunks as f64 - 0.5 * plan.waiting as f64) / threads as f64;
            for (r, &run_waiting) in waiting.iter().enumerate() {
                let own = plan.run_chunks(r).len() as f64 - 0.5 * run_waiting as f64;
                assert!(
                    (own - even).abs() <= 1.5,
                    "{threads} threads, run {r}: {own} chunks of its own, against {even}"
                );
            }
            // The first run waits on nothing, and is shorter than the others.
            assert_eq!(waiting[0], 0);
            assert!(plan.run_chunks(0).len() < plan.run_chunks(threads - 1).len());
        }
    }

    #[test]
    fn guided_runs_cover_the_chunks_in_order_and_shrink_to_the_shortest_run() {
        // Expectation: the runs start at chunk 0 and end at the last chunk, in order; each
        // takes 1 / (threads + 1) of the chunks left, rounded up, but no fewer than the
        // shortest run, and the last takes what is left where less than the shortest run
        // would follow it; so none is shorter than the shortest run, and none is longer than
        // the one before it but the last (the rest it takes is less than two shortest runs).
        for (chunks, threads, min_run) in [(391, 2, 8), (392, 2, 4), (3907, 16, 8), (40, 3, 1)] {
            let starts = guided_starts(chunks, threads, min_run);
            assert_eq!((starts[0], *starts.last().unwrap()), (0, chunks));
            let runs: Vec<usize> = starts.windows(2).map(|w| w[1] - w[0]).collect();
            assert!(runs.iter().all(|&run| run >= min_run), "{runs:?}");
            assert_eq!(runs[0], chunks.div_ceil(threads + 1).max(min_run));
            let last = runs.len() - 1;
            for r in 1..last {
                assert!(runs[r] <= runs[r - 1], "{runs:?}");
            }
            assert!(
                runs[last] < 2 * min_run || runs[last] <= runs[last - 1],
                "{runs:?}"
            );
            assert!(runs.len() > threads, "{runs:?}");
        }
    }

    #[test]
    fn the_plan_takes_guided_runs_where_few_chunks_wait_and_else_one_run_a_thread() {
        // Expectation: chunks whose pairs reach `back` chunks back wait where a run starts, up
        // to `back` of them a run. One chunk back: few enough for runs that shrink (more runs
        // than threads, fused). Thirty back: few enough for one run a thread (30 of 400, one
        // in eight at most) but too many for the shrinking runs (at most one in four), so
        // one run a thread. Every chunk back to grain 0: too many for either, and every grain
        // waits for the second round; its pair pass alone then takes the shrinking runs, down
        // to one chunk (no chunk waits on them), and every chunk after the first run would
        // wait. One thread: one run.
        let chunks = 400;
        let reaching_back = |back: usize| -> Vec<u32> {
            (0..chunks)
                .map(|c: usize| (c.saturating_sub(back) * GRAIN_CHUNK) as u32)
                .collect()
        };
        let guided = guided_starts(chunks, 2, GUIDED_MIN_RUN);
        let one_back = reaching_back(1);
        let plan = SweepPlan::new(&one_back, 2);
        assert!(plan.runs() > 2 && plan.fused, "{plan:?}");
        assert_eq!(plan.waiting, plan.runs() - 1);
        assert_eq!(plan.starts, guided);
        let thirty_back = reaching_back(30);
        let plan = SweepPlan::new(&thirty_back, 2);
        assert_eq!(plan, SweepPlan::even(&thirty_back, 2));
        assert!(
            plan.runs() == 2 && plan.fused && plan.waiting == 30,
            "{plan:?}"
        );
        let all_back = vec![0u32; chunks];
        let plan = SweepPlan::new(&all_back, 2);
        assert!(!SweepPlan::even(&all_back, 2).fused);
        assert!(!plan.fused && plan.waiting_chunks.is_empty(), "{plan:?}");
        assert_eq!(plan.starts, guided_starts(chunks, 2, 1));
        assert_eq!(plan.waiting, chunks - plan.starts[1]);
        assert_eq!(SweepPlan::new(&one_back, 1).runs(), 1);
    }

    #[test]
    fn each_chunks_earliest_first_grain_is_the_least_first_grain_of_its_pairs() {
        // Expectation: the least i over the list's pairs [i, j] with j in the chunk (the
        // chunk's first grain where there is none), found by a scan of every pair.
        let mut world = packing(ModelLevel::Full, false);
        world.step().unwrap();
        let n = world.grains.len();
        let mut expected: Vec<u32> = (0..n.div_ceil(GRAIN_CHUNK))
            .map(|c| (c * GRAIN_CHUNK) as u32)
            .collect();
        for &[i, j] in &world.neighbors.pairs {
            let chunk = &mut expected[j as usize / GRAIN_CHUNK];
            *chunk = (*chunk).min(i);
        }
        assert_eq!(world.earliest_first_grains, expected);
        assert_eq!(earliest_first_grains(&world.neighbors, n), expected);
        // The lattice's rows are longer than a chunk's first grains reach back: some chunk has
        // pairs with the chunk before it.
        assert!(
            expected
                .iter()
                .enumerate()
                .any(|(c, &first)| (first as usize) < c * GRAIN_CHUNK)
        );
    }

    /// The bits of every grain's frame, in grain order.
    fn every_frames_bits(world: &World) -> Vec<Vec<u64>> {
        world
            .frames
            .iter()
            .map(super::super::tests::frame_bits)
            .collect()
    }

    #[test]
    fn the_sweep_gives_the_same_bits_on_any_number_of_threads() {
        // Expectation: a chunk's pairs and grains are the same operations whichever task
        // sweeps them, and whether its grains are computed at once or wait for the second
        // round, or every chunk waits (the two passes one after the other); the sums are added
        // in chunk order. So one thread (every chunk at once) and two, three or eight (runs
        // whose first chunks wait, or the two passes) give the same grains, frames,
        // contacts and totals, bit for bit: in a box and in a periodic cell, at the full level
        // and for rigid discs.
        let (mut fused_with_waiting, mut two_passes) = (false, false);
        for (level, periodic) in [
            (ModelLevel::Full, false),
            (ModelLevel::Full, true),
            (ModelLevel::Rigid, false),
            (ModelLevel::Rigid, true),
        ] {
            let stepped = |threads: usize| {
                in_pool(threads, || {
                    let mut world = packing(level, periodic);
                    for _ in 0..40 {
                        world.step().unwrap();
                    }
                    let plan = SweepPlan::new(&world.earliest_first_grains, threads);
                    let waiting = (0..world.earliest_first_grains.len())
                        .filter(|&c| !plan.fused || plan.waits(&world.earliest_first_grains, c))
                        .count();
                    let contacts: Vec<String> = world
                        .contacts()
                        .map(|(pair, c, _)| format!("{pair:?} {c:?}"))
                        .collect();
                    (
                        format!("{:?}", world.grains),
                        every_frames_bits(&world),
                        contacts,
                        format!("{:?}", world.totals),
                        waiting,
                        plan.fused,
                    )
                })
            };
            let one = stepped(1);
            assert_eq!(one.4, 0, "one thread sweeps every chunk at once");
            assert!(one.2.len() > 5000, "{} contacts", one.2.len());
            for threads in [2, 3, 8] {
                let many = stepped(threads);
                let at = format!("{level:?}, periodic {periodic}, {threads} threads");
                assert!(many.4 > 0, "{at}: no chunk waited");
                fused_with_waiting |= many.5;
                two_passes |= !many.5;
                assert!(one.0 == many.0, "{at}: grains differ");
                assert!(one.1 == many.1, "{at}: frames differ");
                assert!(one.2 == many.2, "{at}: contacts differ");
                assert_eq!(one.3, many.3, "{at}: totals differ");
            }
        }
        // Both ways of sweeping were taken.
        assert!(fused_with_waiting && two_passes);
    }

    #[test]
    fn a_world_without_grains_steps_on_two_threads() {
        // Expectation: no chunk, no run, no task: the step does nothing and does not fail.
        in_pool(2, || {
            let packed = packing(ModelLevel::Rigid, false);
            let mut world = World::new(packed.params, Vec::new(), packed.walls.clone());
            world.step().unwrap();
            assert_eq!(world.sweep_tally.runs, 0);
        });
    }

    #[test]
    fn guided_runs_give_the_same_bits_as_one_thread() {
        // Expectation: as above, with runs that shrink towards the sweep's end, down to one
        // chunk, more runs than threads, each taken by whichever thread comes free: a chunk's
        // operations do not depend on the task that takes it. The packing's eleven chunks are
        // too few for `SweepPlan::new` to choose such runs, so each step is given them.
        for level in [ModelLevel::Full, ModelLevel::Rigid] {
            let stepped = |threads: usize| {
                in_pool(threads, || {
                    let mut world = packing(level, false);
                    let mut guided_steps = 0;
                    for _ in 0..40 {
                        if threads > 1 && !world.earliest_first_grains.is_empty() {
                            let plan =
                                SweepPlan::guided(&world.earliest_first_grains, threads, 1, 1);
                            assert!(plan.runs() > threads && plan.fused, "{plan:?}");
                            assert!(plan.waiting > 0, "{plan:?}");
                            world.sweep_plan = plan;
                        }
                        let builds = world.neighbors.builds;
                        world.step().unwrap();
                        guided_steps += usize::from(world.neighbors.builds == builds);
                    }
                    (
                        format!("{:?}", world.grains),
                        every_frames_bits(&world),
                        format!("{:?}", world.totals),
                        guided_steps,
                    )
                })
            };
            let one = stepped(1);
            for threads in [2, 3] {
                let many = stepped(threads);
                let at = format!("{level:?}, {threads} threads");
                assert!(many.3 >= 20, "{at}: {} steps on guided runs", many.3);
                assert!(one.0 == many.0, "{at}: grains differ");
                assert!(one.1 == many.1, "{at}: frames differ");
                assert_eq!(one.2, many.2, "{at}: totals differ");
            }
        }
    }
}
