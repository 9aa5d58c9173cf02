//! Progress of long runs: an indicatif bar (rate, ETA) when stderr is a terminal; nothing when it
//! is not, or with --quiet; with --log-progress a plain line every 5 s instead (for batch logs,
//! where a bar cannot be drawn).

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

pub struct Progress {
    bar: Option<ProgressBar>,
    plain: Option<Mutex<Instant>>,
    start: Instant,
    total: usize,
    done: AtomicUsize,
    label: String,
}

impl Progress {
    pub fn new(label: &str, total: usize, quiet: bool, log_lines: bool) -> Self {
        let terminal = std::io::stderr().is_terminal() && !log_lines;
        let bar = (!quiet && terminal).then(|| {
            let b = ProgressBar::new(total as u64);
            // A total of 0: the count of runs is open (a fit stops where it converges).
            let template = if total == 0 {
                "{msg} {spinner} {pos} model runs  {per_sec}  {elapsed}"
            } else {
                "{msg} [{bar:30}] {pos}/{len} runs  {per_sec}  ETA {eta}"
            };
            b.set_style(
                ProgressStyle::with_template(template)
                    .expect("template")
                    .progress_chars("=> "),
            );
            if total == 0 {
                b.enable_steady_tick(Duration::from_millis(200));
            }
            b.set_message(label.to_string());
            b
        });
        let plain = (!quiet && log_lines).then(|| Mutex::new(Instant::now()));
        Progress {
            bar,
            plain,
            start: Instant::now(),
            total,
            done: AtomicUsize::new(0),
            label: label.to_string(),
        }
    }

    /// `n` more runs finished (callable from any thread).
    pub(crate) fn inc(&self, n: usize) {
        let done = self.done.fetch_add(n, Ordering::Relaxed) + n;
        if let Some(b) = &self.bar {
            b.inc(n as u64);
        }
        if let Some(last) = &self.plain {
            let mut last = last.lock().expect("progress lock");
            if last.elapsed() >= Duration::from_secs(5) || done == self.total {
                *last = Instant::now();
                let t = self.start.elapsed().as_secs_f64();
                let rate = done as f64 / t.max(1e-9);
                if self.total == 0 {
                    eprintln!(
                        "{}: {done} model runs, {rate:.0} runs/s, elapsed {t:.0} s",
                        self.label
                    );
                    return;
                }
                let eta = (self.total - done) as f64 / rate.max(1e-9);
                eprintln!(
                    "{}: {done}/{} runs ({:.0}%), {rate:.0} runs/s, elapsed {t:.0} s, ETA {eta:.0} s",
                    self.label,
                    self.total,
                    100.0 * done as f64 / self.total.max(1) as f64
                );
            }
        }
    }

    pub fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
        // An open count's last line: how many runs in all (a fixed total's last line is printed
        // when the count reaches it).
        if self.plain.is_some() && self.total == 0 {
            let done = self.done.load(Ordering::Relaxed);
            let t = self.start.elapsed().as_secs_f64();
            eprintln!("{}: {done} model runs in {t:.1} s, done", self.label);
        }
    }

    pub fn elapsed(&self) -> Duration {
        self.start.elapsed()
    }
}
