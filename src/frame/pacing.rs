//! When to draw while a view loads: on a slow GPU, not for every arrival.
//!
//! A viewer draws a frame on every animation frame while its stream loads, so
//! a user sees the forest come in. On a GPU whose frame takes seconds (a
//! software rasteriser: SwiftShader in a browser without a GPU) those frames
//! are what the load waits for: each arrival's frame keeps the GPU busy, the
//! browser stops handing out animation frames while it is, and the stream,
//! polled from them, asks for the next files only when the frame is done. The
//! demo's first complete frame took 150 s on SwiftShader that way, 13 frames of
//! 10 s each for a view whose files were all fetchable in 3 s.
//!
//! [`LoadPacer`] coalesces instead: once a frame took longer than
//! [`SLOW_FRAME_MS`], frames wait while the stream is busy and the view
//! unsettled, and one is drawn when the stream settles, when it has been quiet
//! for a while (it may wait on something only a frame brings), or at least
//! every [`PROGRESS_FRAME_MS`] (a progress frame: the page never looks frozen
//! for long). A fast GPU draws every frame, as before.

/// A frame slower than this (ms, submitted to done) makes a GPU slow.
pub const SLOW_FRAME_MS: f64 = 150.0;
/// A slow GPU draws at least one frame this often while loading (ms), or
/// every three of its frames' times where those are longer.
pub const PROGRESS_FRAME_MS: f64 = 4000.0;
/// A stream with no arrival for this long (ms) gets a frame: it may wait on one.
pub const QUIET_MS: f64 = 400.0;

/// Decides, animation frame by animation frame, whether to draw while loading.
#[derive(Debug, Clone, Default)]
pub struct LoadPacer {
    /// The last frame's time on the GPU (ms, submitted to done), once known.
    last_frame_ms: Option<f64>,
    /// When the last frame was drawn (ms).
    last_draw_ms: Option<f64>,
    /// When the stream last changed (ms), and what it had then.
    last_arrival_ms: f64,
    progress: u64,
    /// Frames held back so far (for the stats and tests).
    held: u64,
}

impl LoadPacer {
    /// A frame's GPU time came back.
    pub fn frame_done(&mut self, ms: f64) {
        self.last_frame_ms = Some(ms);
    }

    /// Whether to draw now (`now_ms`): `settled` says whether the stream has
    /// everything the view needs, `progress` is any count that grows as files
    /// arrive (bytes fetched plus requests started).
    pub fn should_draw(&mut self, now_ms: f64, settled: bool, progress: u64) -> bool {
        if progress != self.progress {
            self.progress = progress;
            self.last_arrival_ms = now_ms;
        }
        let slow = self.last_frame_ms.is_some_and(|ms| ms > SLOW_FRAME_MS);
        let draw = match self.last_draw_ms {
            _ if settled || !slow => true,
            None => true,
            Some(last) => {
                let every = PROGRESS_FRAME_MS.max(3.0 * self.last_frame_ms.unwrap_or(0.0));
                now_ms - self.last_arrival_ms >= QUIET_MS || now_ms - last >= every
            }
        };
        if !draw {
            self.held += 1;
        }
        draw
    }

    /// A frame was drawn at `now_ms`.
    pub fn drew(&mut self, now_ms: f64) {
        self.last_draw_ms = Some(now_ms);
    }

    /// Animation frames that drew nothing so far, for the stream's sake.
    #[must_use]
    pub fn held(&self) -> u64 {
        self.held
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slow GPU loading: frames wait while files arrive, one comes when the
    /// stream settles, progress frames at most every few seconds; a fast GPU
    /// draws every time.
    #[test]
    fn a_slow_gpu_waits_for_the_stream() {
        let mut p = LoadPacer::default();
        // Before any frame's time is known, and on a fast GPU: every frame.
        assert!(p.should_draw(0.0, false, 1));
        p.drew(0.0);
        p.frame_done(16.0);
        assert!(p.should_draw(16.0, false, 2));
        p.drew(16.0);
        // A 10 s frame: arrivals every 100 ms hold frames back…
        p.frame_done(10_000.0);
        let mut t = 100.0;
        let mut drawn = 0;
        // `n` arrivals 100 ms apart, counted from `first`.
        let mut arrivals = |p: &mut LoadPacer, n: u64, first: u64| {
            for i in 0..n {
                if p.should_draw(t, false, first + i) {
                    p.drew(t);
                    drawn += 1;
                }
                t += 100.0;
            }
            (drawn, t)
        };
        assert_eq!(arrivals(&mut p, 200, 3).0, 0, "20 s of arrivals, no frame yet");
        // …but a progress frame comes every 30 s (3 × the frame's time).
        let (drawn, t) = arrivals(&mut p, 110, 1000);
        assert_eq!(drawn, 1, "a progress frame after 30 s");
        assert!(p.held() > 300);
        // Settled: drawn at once.
        assert!(p.should_draw(t, true, 2000));
        p.drew(t);
        // A stream that goes quiet unsettled (waiting on a frame) gets one.
        assert!(!p.should_draw(t + 100.0, false, 2001));
        assert!(!p.should_draw(t + 300.0, false, 2001));
        assert!(p.should_draw(t + 600.0, false, 2001));
    }
}
