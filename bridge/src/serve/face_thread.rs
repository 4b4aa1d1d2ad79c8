//! The thread a face serves on (the PLC face, the OPC UA face), as the service loop
//! supervises it: a tokio runtime of its own, a heartbeat the face ticks, a stop the
//! service sends. A face that stalls (its heartbeat stands still) or ends is seen by
//! [`FaceThread::health`], and the service ends: the face's death is the service's
//! death, and systemd restarts it.

use std::future::Future;
use std::io;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tokio::sync::oneshot;

/// How often a face ticks its heartbeat; ten missed ticks and it is stalled.
const BEAT: Duration = Duration::from_millis(100);

/// How the face is doing, as the service loop sees it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FaceHealth {
    Serving,
    /// Its heartbeat has not moved for this long.
    Stalled(Duration),
    /// Its thread has ended (why).
    Ended(String),
}

/// The runtime a face's thread runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flavour {
    /// One thread (the PLC face: nothing it calls blocks).
    CurrentThread,
    /// Worker threads, so that a call may wait with `tokio::task::block_in_place` while
    /// the face's other tasks (its heartbeat included) go on: the OPC UA face, whose
    /// StartProgram waits for the start to be prepared on the machine thread.
    MultiThread,
}

/// The face's side of the heartbeat: [`Heartbeat::run`] on the face's runtime ticks it
/// for as long as the runtime runs its tasks.
pub struct Heartbeat {
    epoch: Instant,
    /// Milliseconds since `epoch` at the face's last tick.
    beat: Arc<AtomicU64>,
}

impl Heartbeat {
    /// Ticks every `BEAT`, forever: spawn it on the face's runtime.
    pub async fn run(self) {
        let mut every = tokio::time::interval(BEAT);
        loop {
            every.tick().await;
            self.beat();
        }
    }

    /// One tick now. A face whose start takes a while calls it when it is up, before it
    /// says so: the silence is counted from there, not from the thread's start (the OPC
    /// UA face took 4.4 to 5.3 s to come up on emulated CPUs, and the service took that
    /// for a stall and ended itself right after the face said it was ready).
    pub fn beat(&self) {
        self.beat
            .store(self.epoch.elapsed().as_millis() as u64, Ordering::Release);
    }
}

/// A face's thread: its handle, its heartbeat and its stop. Dropping it stops the face
/// and waits for its thread, unless the face no longer answers: a stalled face's loop
/// may never return, and waiting for it would hold the service's stop until systemd
/// kills it (TimeoutStopSec); its thread is left behind, the process ends without it.
pub struct FaceThread {
    /// The face, for the log ("PLC face").
    face: &'static str,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<Result<(), String>>>,
    epoch: Instant,
    beat: Arc<AtomicU64>,
}

impl FaceThread {
    /// Starts thread `name` for the face `face` with a tokio runtime of `flavour` that
    /// runs the future `serve` makes of the face's heartbeat and its stop. The future is
    /// made on the thread, so it need not be `Send`. `Err` from it is why the face
    /// ended.
    pub fn spawn<F, Fut>(
        name: &str,
        face: &'static str,
        flavour: Flavour,
        serve: F,
    ) -> io::Result<Self>
    where
        F: FnOnce(Heartbeat, oneshot::Receiver<()>) -> Fut + Send + 'static,
        Fut: Future<Output = Result<(), String>>,
    {
        let (tx, rx) = oneshot::channel::<()>();
        let epoch = Instant::now();
        let beat = Arc::new(AtomicU64::new(0));
        let heartbeat = Heartbeat {
            epoch,
            beat: beat.clone(),
        };
        let thread = std::thread::Builder::new().name(name.into()).spawn(
            move || -> Result<(), String> {
                let mut builder = match flavour {
                    Flavour::CurrentThread => tokio::runtime::Builder::new_current_thread(),
                    Flavour::MultiThread => {
                        let mut b = tokio::runtime::Builder::new_multi_thread();
                        b.worker_threads(2);
                        b
                    }
                };
                let rt = builder
                    .enable_all()
                    .build()
                    .map_err(|e| format!("cannot start its runtime: {e}"))?;
                rt.block_on(serve(heartbeat, rx))
            },
        )?;
        Ok(Self {
            face,
            stop: Some(tx),
            thread: Some(thread),
            epoch,
            beat,
        })
    }

    /// Ended (and why), stalled (its heartbeat has not moved for ten beats) or serving.
    pub fn health(&mut self) -> FaceHealth {
        if self.thread.as_ref().is_some_and(|t| t.is_finished()) {
            let why = match self.thread.take().map(JoinHandle::join) {
                Some(Ok(Err(e))) => e,
                Some(Ok(Ok(()))) => "its loop returned".into(),
                Some(Err(_)) => "its thread panicked".into(),
                None => "gone".into(),
            };
            return FaceHealth::Ended(why);
        }
        if self.thread.is_none() {
            return FaceHealth::Ended("gone".into());
        }
        let last = Duration::from_millis(self.beat.load(Ordering::Acquire));
        let silent = self.epoch.elapsed().saturating_sub(last);
        if silent > BEAT * 10 {
            FaceHealth::Stalled(silent)
        } else {
            FaceHealth::Serving
        }
    }
}

impl Drop for FaceThread {
    fn drop(&mut self) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        // An ended face's thread is joined by `health`; a serving one is waited for.
        if let FaceHealth::Stalled(_) = self.health() {
            tracing::warn!("the {} is not answering: stopping without it", self.face);
            self.thread.take();
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A face that is up `startup` after its thread started (its runtime blocked until
    /// then, as a slow bring-up blocks it) and, if `beat_when_up`, beats then and starts
    /// its heartbeat (else it never ticks); the health the service sees as soon as the
    /// face says it is up.
    fn health_when_up(startup: Duration, beat_when_up: bool) -> FaceHealth {
        let (up_tx, up_rx) = std::sync::mpsc::channel();
        let mut face = FaceThread::spawn(
            "test-slow-face",
            "test face",
            Flavour::CurrentThread,
            move |heartbeat, stop| async move {
                std::thread::sleep(startup);
                if beat_when_up {
                    heartbeat.beat();
                    tokio::spawn(heartbeat.run());
                }
                let _ = up_tx.send(());
                let _ = stop.await;
                Ok(())
            },
        )
        .unwrap();
        up_rx.recv().unwrap();
        face.health()
    }

    #[test]
    fn a_face_that_beats_when_up_is_serving_however_long_it_took() {
        let startup = BEAT * 15;
        let health = health_when_up(startup, true);
        assert!(
            !matches!(health, FaceHealth::Stalled(d) if d >= startup),
            "{health:?}: the start-up was counted as silence"
        );
    }

    #[test]
    fn a_face_that_never_beat_is_silent_since_its_thread_started() {
        // The silence is counted from the thread's start until the first beat: the check
        // above is not vacuous (the OPC UA face's first beat came after its bring-up).
        let startup = BEAT * 15;
        let health = health_when_up(startup, false);
        assert!(
            matches!(health, FaceHealth::Stalled(d) if d >= startup),
            "{health:?}"
        );
    }
}
