//! The GPU thread's queue, fair between clients.
//!
//! A client is the peer's IP address: every connection from one host shares its queue. Each
//! client may have `max_client_queue` renders waiting, and all clients together `max_queue`.
//! The GPU thread takes renders in start-time fair queueing order (Goyal et al. 1996, with
//! every render costing one): a render's tag is one more than its client's previous render's,
//! or the tag of the render on the GPU when the client had none waiting, and the smallest tag
//! goes first (the oldest among equals). So clients take turns, and a client that was not
//! waiting waits for at most the render on the GPU and one render of each other waiting
//! client, however many those send. Scene creation and deletion ("control" jobs) go ahead of
//! renders; they are bounded by `max_scenes`, not here.
//!
//! A render whose requester has gone (the client disconnected, the stream closed) leaves the
//! queue before every push, pop and count ([`FairQueue::dropping_abandoned`]): it holds no
//! place of `max_client_queue` or `max_queue` and never reaches the GPU.
//!
//! `Retry-After` comes from the queue wait measured when the GPU thread took the client's
//! recent renders (smoothed), or, for a client with none waiting, everyone's.

use std::collections::{HashMap, VecDeque};
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use axum::extract::{ConnectInfo, FromRequestParts};
use axum::http::request::Parts;

/// Weight of the newest measurement in the smoothed queue waits.
const SMOOTHING: f64 = 0.3;

/// Who sent a job: the peer's IP address, or the unspecified address for requests that did
/// not come over a socket (the router driven in-process).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ClientId(pub IpAddr);

impl ClientId {
    pub const UNKNOWN: ClientId = ClientId(IpAddr::V4(Ipv4Addr::UNSPECIFIED));
}

impl<S: Send + Sync> FromRequestParts<S> for ClientId {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(parts: &mut Parts, _: &S) -> Result<Self, Self::Rejection> {
        Ok(parts.extensions.get::<ConnectInfo<SocketAddr>>().map_or(ClientId::UNKNOWN, |c| ClientId(c.0.ip())))
    }
}

/// Why a render was not queued.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Refused {
    /// `max_queue` renders are waiting in all.
    Full { waiting: usize, retry_after: Option<Duration> },
    /// This client has `max_client_queue` renders waiting.
    ClientFull { waiting: usize, retry_after: Option<Duration> },
    /// The queue is closed (the GPU thread is stopping).
    Closed,
}

/// A job taken by the GPU thread, and how long it waited (renders only).
pub struct Taken<T> {
    pub job: T,
    pub waited: Option<Duration>,
}

/// The queue; the GPU thread blocks in [`FairQueue::pop`].
pub struct FairQueue<T> {
    state: Mutex<State<T>>,
    ready: Condvar,
    max_total: usize,
    max_per_client: usize,
    /// Whether a queued render's requester has gone.
    abandoned: fn(&T) -> bool,
}

struct State<T> {
    control: VecDeque<T>,
    /// Only clients with renders waiting have an entry (the map is bounded by `max_queue`).
    clients: HashMap<ClientId, ClientQueue<T>>,
    /// The tag of the render handed out last.
    virtual_time: u64,
    /// Renders queued so far: orders renders of equal tags.
    sequence: u64,
    waiting: usize,
    /// Smoothed queue wait of every render, s.
    wait: Option<f64>,
    closed: bool,
}

struct ClientQueue<T> {
    jobs: VecDeque<Queued<T>>,
    /// The tag of the client's next render (at least the virtual time).
    next_tag: u64,
    /// Smoothed queue wait of this client's renders, s.
    wait: Option<f64>,
}

struct Queued<T> {
    job: T,
    enqueued: Instant,
    tag: u64,
    sequence: u64,
}

impl<T> FairQueue<T> {
    pub fn new(max_total: usize, max_per_client: usize) -> FairQueue<T> {
        FairQueue {
            state: Mutex::new(State {
                control: VecDeque::new(),
                clients: HashMap::new(),
                virtual_time: 0,
                sequence: 0,
                waiting: 0,
                wait: None,
                closed: false,
            }),
            ready: Condvar::new(),
            max_total,
            max_per_client,
            abandoned: |_| false,
        }
    }

    /// The same queue, where renders for which `abandoned` holds are dropped unrun.
    pub fn dropping_abandoned(self, abandoned: fn(&T) -> bool) -> FairQueue<T> {
        FairQueue { abandoned, ..self }
    }

    /// The state, locked, with the abandoned renders gone.
    fn lock_pruned(&self) -> MutexGuard<'_, State<T>> {
        let mut state = self.lock();
        state.prune(self.abandoned);
        state
    }

    fn lock(&self) -> MutexGuard<'_, State<T>> {
        self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Queues a render of `client`, or refuses at once.
    pub fn push(&self, client: ClientId, job: T) -> Result<(), Refused> {
        let mut state = self.lock_pruned();
        if state.closed {
            return Err(Refused::Closed);
        }
        let own = state.clients.get(&client);
        let retry_after = own.and_then(|q| q.wait).or(state.wait).map(Duration::from_secs_f64);
        let own_waiting = own.map_or(0, |q| q.jobs.len());
        if own_waiting >= self.max_per_client {
            return Err(Refused::ClientFull { waiting: own_waiting, retry_after });
        }
        if state.waiting >= self.max_total {
            return Err(Refused::Full { waiting: state.waiting, retry_after });
        }
        let (virtual_time, sequence) = (state.virtual_time, state.sequence);
        let queue = state.clients.entry(client).or_insert_with(|| ClientQueue {
            jobs: VecDeque::new(),
            next_tag: virtual_time,
            wait: None,
        });
        let tag = queue.next_tag.max(virtual_time);
        queue.next_tag = tag + 1;
        queue.jobs.push_back(Queued { job, enqueued: Instant::now(), tag, sequence });
        state.sequence += 1;
        state.waiting += 1;
        drop(state);
        self.ready.notify_one();
        Ok(())
    }

    /// Queues a control job (ahead of every render).
    pub fn push_control(&self, job: T) -> Result<(), Refused> {
        let mut state = self.lock();
        if state.closed {
            return Err(Refused::Closed);
        }
        state.control.push_back(job);
        drop(state);
        self.ready.notify_one();
        Ok(())
    }

    /// The next job: a control job if any, else the render with the smallest tag. Blocks
    /// while the queue is empty; `None` once it is closed and empty.
    pub fn pop(&self) -> Option<Taken<T>> {
        let mut state = self.lock();
        loop {
            state.prune(self.abandoned);
            if let Some(job) = state.control.pop_front() {
                return Some(Taken { job, waited: None });
            }
            let next =
                state.clients.iter().filter_map(|(&c, q)| q.jobs.front().map(|j| ((j.tag, j.sequence), c))).min();
            if let Some((_, client)) = next {
                return Some(state.take_render(client));
            }
            if state.closed {
                return None;
            }
            state = self.ready.wait(state).unwrap_or_else(|poisoned| poisoned.into_inner());
        }
    }

    /// Refuses new jobs; those queued are still handed out by [`FairQueue::pop`].
    pub fn close(&self) {
        self.lock().closed = true;
        self.ready.notify_all();
    }

    /// Renders waiting, all clients together.
    pub fn waiting(&self) -> usize {
        self.lock_pruned().waiting
    }

    pub fn capacity(&self) -> usize {
        self.max_total
    }
}

impl<T> State<T> {
    /// Drops the renders for which `abandoned` holds. A client left with none loses its entry
    /// (and so its tag), as when its last render is taken.
    fn prune(&mut self, abandoned: fn(&T) -> bool) {
        let mut dropped = 0;
        self.clients.retain(|_, queue| {
            let before = queue.jobs.len();
            queue.jobs.retain(|queued| !abandoned(&queued.job));
            dropped += before - queue.jobs.len();
            !queue.jobs.is_empty()
        });
        self.waiting -= dropped;
    }

    /// The oldest render of `client` (which has one waiting).
    fn take_render(&mut self, client: ClientId) -> Taken<T> {
        let queue = self.clients.get_mut(&client).expect("a client with a render waiting");
        let Queued { job, enqueued, tag, .. } = queue.jobs.pop_front().expect("a render waiting");
        self.virtual_time = tag;
        let waited = enqueued.elapsed();
        let smooth =
            |old: Option<f64>| Some(old.map_or(waited.as_secs_f64(), |w| w + SMOOTHING * (waited.as_secs_f64() - w)));
        queue.wait = smooth(queue.wait);
        if queue.jobs.is_empty() {
            self.clients.remove(&client);
        }
        self.wait = smooth(self.wait);
        self.waiting -= 1;
        Taken { job, waited: Some(waited) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn client(last: u8) -> ClientId {
        ClientId(IpAddr::V4(Ipv4Addr::new(127, 0, 0, last)))
    }

    fn drain(queue: &FairQueue<&'static str>) -> Vec<&'static str> {
        queue.close();
        std::iter::from_fn(|| queue.pop().map(|t| t.job)).collect()
    }

    #[test]
    fn clients_are_served_round_robin_and_control_jobs_first() {
        let queue = FairQueue::new(16, 4);
        for job in ["a1", "a2", "a3", "a4"] {
            queue.push(client(1), job).expect("room");
        }
        queue.push(client(2), "b1").expect("room");
        queue.push_control("add").expect("open");
        queue.push(client(2), "b2").expect("room");
        queue.push(client(3), "c1").expect("room");
        assert_eq!(queue.waiting(), 7);
        assert_eq!(drain(&queue), ["add", "a1", "b1", "c1", "a2", "b2", "a3", "a4"]);
        assert_eq!(queue.waiting(), 0);
    }

    #[test]
    fn a_client_that_was_not_waiting_goes_before_one_just_served() {
        let queue = FairQueue::new(16, 4);
        queue.push(client(1), "a1").expect("room");
        queue.push(client(1), "a2").expect("room");
        assert_eq!(queue.pop().map(|t| t.job), Some("a1"));
        queue.push(client(1), "a3").expect("room");
        queue.push(client(2), "b1").expect("room");
        assert_eq!(drain(&queue), ["b1", "a2", "a3"]);
    }

    #[test]
    fn each_client_and_the_total_are_bounded() {
        let queue = FairQueue::new(3, 2);
        queue.push(client(1), "a1").expect("room");
        queue.push(client(1), "a2").expect("room");
        assert!(matches!(queue.push(client(1), "a3"), Err(Refused::ClientFull { waiting: 2, .. })));
        queue.push(client(2), "b1").expect("room");
        assert!(matches!(queue.push(client(3), "c1"), Err(Refused::Full { waiting: 3, .. })));
        assert_eq!(queue.pop().map(|t| t.job), Some("a1"));
        queue.push(client(3), "c1").expect("room again");
        queue.close();
        assert_eq!(queue.push(client(4), "d1"), Err(Refused::Closed));
        assert_eq!(queue.push_control("add"), Err(Refused::Closed));
        assert_eq!(drain(&queue), ["b1", "c1", "a2"]);
    }

    #[test]
    fn retry_after_is_the_measured_wait_of_the_clients_renders() {
        let queue = FairQueue::new(8, 1);
        queue.push(client(1), "a1").expect("room");
        let Err(Refused::ClientFull { retry_after, .. }) = queue.push(client(1), "a2") else { panic!("refused") };
        assert_eq!(retry_after, None, "nothing measured yet");
        std::thread::sleep(Duration::from_millis(60));
        let waited = queue.pop().and_then(|t| t.waited).expect("a render");
        assert!(waited >= Duration::from_millis(60), "{waited:?}");
        queue.push(client(1), "a2").expect("room");
        let Err(Refused::ClientFull { retry_after, .. }) = queue.push(client(1), "a3") else { panic!("refused") };
        // One measurement: the smoothed wait is that wait.
        assert_eq!(retry_after, Some(waited));
        // Another client with nothing waiting is told everyone's wait when the total is full.
        let full = FairQueue::new(1, 1);
        full.push(client(1), "a1").expect("room");
        assert!(matches!(full.push(client(2), "b1"), Err(Refused::Full { retry_after: None, .. })));
    }

    #[test]
    fn abandoned_renders_leave_the_queue_and_free_their_places() {
        let gone = |job: &&'static str| job.starts_with("gone");
        let queue = FairQueue::new(3, 2).dropping_abandoned(gone);
        queue.push(client(1), "gone1").expect("room");
        queue.push(client(1), "gone2").expect("room");
        queue.push(client(2), "gone3").expect("room");
        // Neither this client's two places nor the total's three are held by the gone.
        assert_eq!(queue.waiting(), 0);
        queue.push(client(1), "a1").expect("room");
        queue.push(client(1), "a2").expect("room");
        queue.push(client(3), "c1").expect("room");
        assert!(matches!(queue.push(client(1), "a3"), Err(Refused::ClientFull { waiting: 2, .. })));
        assert_eq!(drain(&queue), ["a1", "c1", "a2"]);
        // A render abandoned after it was queued is not handed out either.
        static A1_GONE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
        let queue = FairQueue::new(4, 4)
            .dropping_abandoned(|job: &&'static str| *job == "a1" && A1_GONE.load(std::sync::atomic::Ordering::SeqCst));
        queue.push(client(1), "a1").expect("room");
        queue.push(client(1), "a2").expect("room");
        assert_eq!(queue.waiting(), 2);
        A1_GONE.store(true, std::sync::atomic::Ordering::SeqCst);
        assert_eq!(drain(&queue), ["a2"]);
    }

    #[test]
    fn pop_blocks_until_a_job_arrives() {
        let queue = std::sync::Arc::new(FairQueue::new(4, 4));
        let popper = {
            let queue = queue.clone();
            std::thread::spawn(move || queue.pop().map(|t| t.job))
        };
        std::thread::sleep(Duration::from_millis(20));
        queue.push(client(1), "a1").expect("room");
        assert_eq!(popper.join().expect("joined"), Some("a1"));
    }
}
