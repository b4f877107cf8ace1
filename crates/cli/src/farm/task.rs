//! What one farm task does, the same under every engine: which exit status it ends with,
//! which frames it may skip when it is run again, and how it reports its progress.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use nerfx_core::error::Error;
use nerfx_core::image::read_exr_channels;

/// How a task ends. The engines' retry settings are wired to these numbers: a bad input fails
/// the same way on every machine, so it is never retried; a transient failure may pass on
/// another attempt or another machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExitStatus {
    /// Every frame was written (or already whole): 0.
    Done,
    /// The input cannot be rendered (a malformed or missing scene, shot or graph, a bad
    /// option): 2. The engine must not retry it.
    BadInput,
    /// Something outside the input failed (a full disk, a failing network mount, an interrupted
    /// write): 75, `EX_TEMPFAIL` of `sysexits.h`. The engine may retry it.
    Transient,
}

impl ExitStatus {
    /// The process exit code.
    pub fn code(self) -> u8 {
        match self {
            ExitStatus::Done => 0,
            ExitStatus::BadInput => 2,
            ExitStatus::Transient => 75,
        }
    }

    /// How an error ends a task. What the input says (its format, its values, a feature it
    /// asks for) is the same on the next attempt; so is a file that is not there or may not be
    /// read. Every other I/O failure may pass.
    pub fn of(error: &Error) -> ExitStatus {
        use std::io::ErrorKind;
        match error {
            Error::Format { .. } | Error::Invalid { .. } | Error::Unsupported(_) => {
                ExitStatus::BadInput
            }
            Error::Io { source, .. } => match source.kind() {
                ErrorKind::NotFound
                | ErrorKind::PermissionDenied
                | ErrorKind::InvalidData
                | ErrorKind::InvalidInput
                | ErrorKind::IsADirectory
                | ErrorKind::NotADirectory
                | ErrorKind::UnexpectedEof => ExitStatus::BadInput,
                _ => ExitStatus::Transient,
            },
        }
    }
}

/// Whether a frame at `output` may be skipped on a rerun: it reads back whole as an EXR (not
/// merely present: a file cut short by a dead machine does not read) and it was written after
/// every one of `inputs` last changed.
pub fn is_done(output: &Path, inputs: &[PathBuf]) -> bool {
    let Some(written) = modified(output) else {
        return false;
    };
    let newer = inputs
        .iter()
        .all(|input| modified(input).is_some_and(|changed| changed <= written));
    newer && read_exr_channels(output).is_ok_and(|channels| !channels.is_empty())
}

fn modified(path: &Path) -> Option<SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

/// How a task reports its progress: in the convention of the engine that runs it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Progress {
    /// One line per frame (`frame 1001 → out/comp.1001.exr`): what Slurm's and OpenCue's
    /// logs show.
    #[default]
    Plain,
    /// Open Job Description's `openjd_progress: <percent>` and `openjd_status: <text>` lines,
    /// which Deadline Cloud's monitor shows for the task, besides the plain lines.
    Openjd,
}

impl Progress {
    /// The lines that report frame `done` of `total` (counting from 1) finished as `what`.
    pub fn frame_lines(self, done: usize, total: usize, what: &str) -> Vec<String> {
        let mut lines = vec![what.to_string()];
        if self == Progress::Openjd {
            let percent = 100.0 * done as f64 / total.max(1) as f64;
            lines.push(format!("openjd_progress: {percent:.1}"));
            lines.push(format!("openjd_status: {done}/{total} frames: {what}"));
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nerfx_core::image::{write_exr, Plane, Planes};
    use std::io;

    #[test]
    fn exit_statuses_follow_the_cause() {
        let io = |kind| Error::io("x", io::Error::new(kind, "why"));
        assert_eq!(
            ExitStatus::of(&Error::invalid("a", "b")),
            ExitStatus::BadInput
        );
        assert_eq!(
            ExitStatus::of(&Error::format("a", "", "b")),
            ExitStatus::BadInput
        );
        assert_eq!(
            ExitStatus::of(&io(io::ErrorKind::NotFound)),
            ExitStatus::BadInput
        );
        assert_eq!(
            ExitStatus::of(&io(io::ErrorKind::StorageFull)),
            ExitStatus::Transient
        );
        assert_eq!(
            ExitStatus::of(&io(io::ErrorKind::TimedOut)),
            ExitStatus::Transient
        );
        assert_eq!(
            [
                ExitStatus::Done,
                ExitStatus::BadInput,
                ExitStatus::Transient
            ]
            .map(ExitStatus::code),
            [0, 2, 75]
        );
    }

    #[test]
    fn a_frame_is_done_when_it_reads_back_whole_and_is_newer_than_its_inputs() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("scene.json");
        std::fs::write(&input, "{}").unwrap();
        let frame = dir.path().join("frame.exr");
        assert!(!is_done(&frame, std::slice::from_ref(&input)));
        let planes = Planes {
            width: 4,
            height: 3,
            rgb: None,
            alpha: Some(Plane::filled(4, 3, 0.5)),
            depth_z: None,
            depth_ray: None,
            depth_median: None,
        };
        write_exr(&frame, &planes).unwrap();
        assert!(is_done(&frame, std::slice::from_ref(&input)));
        // Cut short, as a machine dying mid-copy would leave it.
        let bytes = std::fs::read(&frame).unwrap();
        std::fs::write(&frame, &bytes[..bytes.len() / 2]).unwrap();
        assert!(!is_done(&frame, std::slice::from_ref(&input)));
        // Whole again, but the input changed after it was written.
        std::fs::write(&frame, &bytes).unwrap();
        let later = SystemTime::now() + std::time::Duration::from_secs(60);
        std::fs::File::options()
            .write(true)
            .open(&input)
            .unwrap()
            .set_modified(later)
            .unwrap();
        assert!(!is_done(&frame, std::slice::from_ref(&input)));
    }

    #[test]
    fn openjd_progress_lines() {
        assert_eq!(Progress::Plain.frame_lines(1, 4, "frame 7"), ["frame 7"]);
        assert_eq!(
            Progress::Openjd.frame_lines(1, 4, "frame 7"),
            [
                "frame 7",
                "openjd_progress: 25.0",
                "openjd_status: 1/4 frames: frame 7"
            ]
        );
    }
}
