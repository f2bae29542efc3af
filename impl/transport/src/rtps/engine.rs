//! `rustdds`'s own threads (an event loop and discovery per participant): finding a new participant's threads by
//! name in `/proc/self/task`, and telling whether one has ended (see the parent module's documentation,
//! "Recovery").

use std::sync::Mutex;

/// One of the threads `rustdds` 0.15 runs per participant ("RustDDS Participant N event loop", "RustDDS discovery
/// thread"), known by its Linux thread id and its name as `/proc` shows it (15 bytes at most). While a participant
/// exists, both threads must run: each ends only when the participant is dropped — or, in `rustdds` 0.15, on any
/// error of its `poll` (see the module documentation, "Recovery").
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct EngineThread {
    pub(super) tid: u32,
    pub(super) name: String,
}

/// Where Linux lists this process's threads.
const TASKS_DIR: &str = "/proc/self/task";
/// Prefix of the names of `rustdds`'s threads.
const ENGINE_THREAD_PREFIX: &str = "RustDDS";

/// Participants are created one at a time in this process, so that the `rustdds` threads that appear during a
/// creation are that creation's (see [`EngineThread`]).
pub(super) static CREATING_PARTICIPANTS: Mutex<()> = Mutex::new(());

impl EngineThread {
    /// Whether this process's threads can be watched: `/proc/self/task` can be read (Linux).
    pub(super) fn watchable() -> bool {
        std::fs::read_dir(TASKS_DIR).is_ok()
    }

    /// The `rustdds` threads of this process now; empty where `/proc/self/task` cannot be read (not Linux).
    pub(super) fn all() -> Vec<EngineThread> {
        let Ok(tasks) = std::fs::read_dir(TASKS_DIR) else { return Vec::new() };
        tasks
            .filter_map(|task| {
                let task = task.ok()?;
                let tid = task.file_name().to_str()?.parse().ok()?;
                let name = std::fs::read_to_string(task.path().join("comm")).ok()?;
                let name = name.trim_end_matches('\n');
                name.starts_with(ENGINE_THREAD_PREFIX).then(|| EngineThread { tid, name: name.to_owned() })
            })
            .collect()
    }

    /// Whether the thread still runs: it is in `/proc/self/task` under its name (a thread id reused by another
    /// thread has another name). An unreadable entry for any other reason than its absence counts as running.
    pub(super) fn alive(&self) -> bool {
        match std::fs::read_to_string(format!("{TASKS_DIR}/{}/comm", self.tid)) {
            Ok(name) => name.trim_end_matches('\n') == self.name,
            Err(error) => error.kind() != std::io::ErrorKind::NotFound,
        }
    }
}

/// The `rustdds` threads of the participants one call created: whoever owns participants outside this transport
/// (the ROS 2 bridge's own) watches them the same way, and rebuilds when [`EngineWatch::ended`] says one is gone
/// (after a SIGSTOP/SIGCONT, see the module documentation of `transport::rtps`, "Recovery").
#[derive(Clone, Debug, Default)]
pub struct EngineWatch {
    threads: Vec<EngineThread>,
}

impl EngineWatch {
    /// Runs `create` (which creates participants) with participant creation in this process held off meanwhile,
    /// and returns its result with the `rustdds` threads that appeared during it.
    pub fn create<R>(create: impl FnOnce() -> R) -> (R, EngineWatch) {
        let _creating = CREATING_PARTICIPANTS.lock().unwrap_or_else(|p| p.into_inner());
        let before = EngineThread::all();
        let created = create();
        let threads = EngineThread::all().into_iter().filter(|t| !before.contains(t)).collect();
        (created, EngineWatch { threads })
    }

    /// The name of a watched thread that has ended, if one has (`rustdds` cannot send or receive without it).
    pub fn ended(&self) -> Option<&str> {
        self.threads.iter().find(|thread| !thread.alive()).map(|thread| thread.name.as_str())
    }

    /// How many threads are watched (2 per participant where `/proc/self/task` can be read, else 0).
    pub fn threads(&self) -> usize {
        self.threads.len()
    }

    pub(super) fn into_threads(self) -> Vec<EngineThread> {
        self.threads
    }
}
