//! The one source skeleton: every reader (TUM RGB-D, KITTI, image folders) and the generator
//! is a sequence of frames by index; reading frame `seq`, stamping its messages, `on_error`,
//! counting what was skipped and the sequence's length are [`SequenceSource`]'s, and a reader
//! says only how one frame becomes messages ([`Frames`]).

use std::sync::Arc;

use dynaflow_engine::msg::{Header, Pose};
use dynaflow_engine::op::{Context, OpError, Out, Outputs, Source};
use dynaflow_engine::param_enum;

param_enum! {
    /// What an unreadable frame does.
    pub enum OnError { Fail = "fail", Skip = "skip" }
}

/// A sequence of frames a source streams.
pub(crate) trait Frames: Send + 'static {
    /// One frame as the reader returns it.
    type Frame;
    /// Frames in the sequence.
    fn len(&self) -> u64;
    /// Frame `i`; `None` past the end. An error names the file.
    fn read(&mut self, i: u64) -> Result<Option<Self::Frame>, dynaflow_datasets::Error>;
    /// Its sensor time, seconds.
    fn stamp(frame: &Self::Frame) -> f64;
    /// Its messages; `header` is the camera's (the frame's `seq` and stamp).
    fn emit(&self, frame: Self::Frame, header: Header) -> Outputs;
    /// At the start of the run, with the node's seed (the generator seeds itself here).
    fn start(&mut self, _seed: u64) {}
}

/// Sends `world_from_cam` on a ground-truth pose port, stamped as `header` in the `world` frame.
pub(crate) fn ground_truth_pose(out: &mut Outputs, port: &Out<Pose>, header: &Header, world_from_cam: Pose) {
    port.push(out, Header { frame_id: "world".into(), ..header.clone() }, world_from_cam);
}

/// A source over [`Frames`]: frame `seq` at `seq`, the end where the sequence ends.
pub(crate) struct SequenceSource<F: Frames> {
    frames: F,
    /// Where the frames come from (the skip warning names it).
    origin: String,
    on_error: OnError,
    skipped: u64,
    frame_id: Arc<str>,
}

impl<F: Frames> SequenceSource<F> {
    /// Streams `frames` (read from `origin`) in the `camera` frame.
    pub(crate) fn new(frames: F, origin: &std::path::Path, on_error: OnError) -> Self {
        Self { frames, origin: origin.display().to_string(), on_error, skipped: 0, frame_id: "camera".into() }
    }
}

impl<F: Frames> Source for SequenceSource<F> {
    fn start(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        self.frames.start(ctx.seed);
        Ok(())
    }

    fn next(&mut self, _ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError> {
        match self.frames.read(seq) {
            Ok(None) => Ok(None),
            Ok(Some(f)) => {
                let header = Header { seq, stamp: F::stamp(&f), frame_id: self.frame_id.clone() };
                Ok(Some(self.frames.emit(f, header)))
            }
            Err(e) if self.on_error == OnError::Skip => {
                tracing::warn!("skipping frame {seq}: {e}");
                self.skipped += 1;
                Ok(Some(Outputs::new()))
            }
            Err(e) => Err(OpError::library(e)),
        }
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), OpError> {
        if self.skipped > 0 {
            tracing::warn!("{}: skipped {} of {} frames", self.origin, self.skipped, self.frames.len());
        }
        Ok(())
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.frames.len())
    }
}
