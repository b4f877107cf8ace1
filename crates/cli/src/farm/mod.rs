//! Jobs for the render-farm engines studios already run: Slurm job arrays ([`slurm`]), Open
//! Job Description templates for AWS Deadline Cloud ([`openjd`]) and OpenCue PyOutline
//! scripts ([`opencue`]). nerfx schedules nothing across machines itself: a job cuts the
//! frames into chunks (and, with a split frame, each frame into stripes), and every task runs
//! `nerfx render` on its share as [`task`] describes.

pub mod opencue;
pub mod openjd;
pub mod slurm;
pub mod split;
pub mod task;
mod yaml;

use std::path::{Path, PathBuf};

use crate::frames::parse_frames;
use nerfx_core::error::{Error, Result};
use nerfx_core::render::TILE_SIZE;

pub use split::{assemble, Stripe};
pub use task::{is_done, ExitStatus, Progress};

/// A render job as every engine runs it: what to render, which frames, how they are shared
/// out, and what a task may use.
#[derive(Clone, Debug, PartialEq)]
pub struct FarmJob {
    /// The job's name in the engine.
    pub name: String,
    /// The `nerfx` program every worker runs (an absolute path visible to every worker).
    pub program: PathBuf,
    /// What `nerfx render` takes: a scene and a shot, or a node graph (absolute paths).
    pub inputs: Vec<PathBuf>,
    /// The output pattern, absolute, with `#` for the frame number.
    pub output: PathBuf,
    /// The frames, in order.
    pub frames: Vec<i64>,
    /// Frames per task (the last task may have fewer).
    pub chunk: usize,
    /// Stripes each frame is cut into (1: frames are rendered whole).
    pub split: u32,
    /// Further `nerfx render` options, passed through as given (`--quality final`, …).
    pub render_args: Vec<String>,
    /// CPUs a task asks for.
    pub cpus: Option<u32>,
    /// Memory a task asks for, in MiB.
    pub memory_mib: Option<u64>,
    /// How often the engine may run a task again after a transient failure.
    pub retries: u32,
    /// What the inputs read besides themselves: a scene's field files and run folders.
    pub sources: Vec<PathBuf>,
}

impl FarmJob {
    /// A job rendering `inputs` for `frames` (a frame list as `nerfx render --frames` takes
    /// it) to `output`, `chunk` frames per task, each frame in `split` stripes. Paths become
    /// absolute (a job runs from any folder), the inputs must exist, and the output pattern
    /// must number its frames: every task writes files of its own.
    pub fn new(
        inputs: &[PathBuf],
        frames: &str,
        chunk: usize,
        output: &Path,
        split: u32,
    ) -> Result<FarmJob> {
        if chunk == 0 {
            return Err(Error::invalid(
                "--chunk",
                "a chunk holds at least one frame",
            ));
        }
        split::check_count(split)?;
        if !output.to_string_lossy().contains('#') {
            return Err(Error::invalid(
                format!("output {}", output.display()),
                "a farm job writes one file per frame: put the frame number's place in the \
                 name as #### (out/comp.####.exr)",
            ));
        }
        let frames = parse_frames(frames)?;
        let inputs = inputs
            .iter()
            .map(|input| {
                std::fs::metadata(input).map_err(|e| Error::io(input, e))?;
                absolute(input)
            })
            .collect::<Result<Vec<_>>>()?;
        let program = std::env::current_exe().map_err(|e| Error::io("nerfx", e))?;
        let output = absolute(output)?;
        let name = output
            .file_name()
            .map(|n| {
                let n = n.to_string_lossy();
                n.split('.')
                    .next()
                    .unwrap_or_default()
                    .trim_matches('#')
                    .to_string()
            })
            .filter(|n| !n.is_empty())
            .unwrap_or_else(|| "render".into());
        Ok(FarmJob {
            name: format!("nerfx-{name}"),
            program,
            inputs,
            output,
            frames,
            chunk,
            split,
            render_args: Vec::new(),
            cpus: None,
            memory_mib: None,
            retries: 2,
            sources: Vec::new(),
        })
    }

    /// Checks what can be checked before the job is submitted, so that a bad job fails here
    /// and not on every worker: the scene's sources must exist, a shot (the second input)
    /// must hold every frame, and a split frame must have a row of tiles for each stripe. (A
    /// graph is checked when it renders.)
    pub fn check(&self) -> Result<()> {
        let Some(shot_path) = self.inputs.get(1) else {
            return Ok(());
        };
        for source in &self.sources {
            std::fs::metadata(source).map_err(|e| Error::io(source, e))?;
        }
        let shot = nerfx_core::camera::read_shot(shot_path, nerfx_core::demo::NERF_OBJECT)?;
        for &frame in &self.frames {
            let camera = shot.frame(frame)?.camera(&shot)?;
            if self.split > 1 {
                let full = camera.full_window();
                Stripe::new(self.split, self.split)?.window(
                    full.width(),
                    full.height(),
                    TILE_SIZE,
                )?;
            }
        }
        Ok(())
    }

    /// The frames of each task, in order.
    pub fn chunks(&self) -> Vec<&[i64]> {
        self.frames.chunks(self.chunk).collect()
    }

    /// The folder the frames are written to.
    pub fn output_dir(&self) -> &Path {
        self.output.parent().unwrap_or(Path::new("/"))
    }

    /// The arguments of `nerfx` that render `frames` (a frame list), the whole frames or
    /// `stripe` (`K/N`) of each, reporting progress as `progress` does.
    pub fn render_args(
        &self,
        frames: &str,
        stripe: Option<&str>,
        progress: Progress,
    ) -> Vec<String> {
        let mut args = vec!["render".to_string()];
        args.extend(self.inputs.iter().map(|p| p.display().to_string()));
        args.extend([
            "--frames".into(),
            frames.to_string(),
            "-o".into(),
            self.output.display().to_string(),
            "--resume".into(),
            "--progress".into(),
            progress_name(progress).into(),
        ]);
        if let Some(stripe) = stripe {
            args.extend(["--stripe".into(), stripe.to_string()]);
        }
        args.extend(self.render_args.iter().cloned());
        args
    }

    /// The arguments of `nerfx` that join the stripes of `frames` into the frames.
    pub fn assemble_args(&self, frames: &str, progress: Progress) -> Vec<String> {
        vec![
            "assemble".into(),
            "--frames".into(),
            frames.to_string(),
            "--split-frame".into(),
            self.split.to_string(),
            "-o".into(),
            self.output.display().to_string(),
            "--progress".into(),
            progress_name(progress).into(),
        ]
    }
}

fn progress_name(progress: Progress) -> &'static str {
    match progress {
        Progress::Plain => "plain",
        Progress::Openjd => "openjd",
    }
}

/// `path` as an absolute path (not resolving links: a path on a shared mount stays the path
/// every worker sees).
fn absolute(path: &Path) -> Result<PathBuf> {
    std::path::absolute(path).map_err(|e| Error::io(path, e))
}

/// A frame list written as compactly as `nerfx render --frames` reads it: runs of a constant
/// step become `first-last` or `first-lastxstep`, the rest stays a comma list.
///
/// ```
/// use nerfx::farm::frame_spec;
/// assert_eq!(frame_spec(&[1, 2, 3, 4]), "1-4");
/// assert_eq!(frame_spec(&[1, 3, 5, 9]), "1-5x2,9");
/// assert_eq!(frame_spec(&[7]), "7");
/// ```
pub fn frame_spec(frames: &[i64]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < frames.len() {
        let first = frames[i];
        let step = frames.get(i + 1).map(|next| next.wrapping_sub(first));
        let mut last = i;
        if let Some(step) = step.filter(|&s| s > 0) {
            while frames
                .get(last + 1)
                .is_some_and(|&f| f.checked_sub(frames[last]) == Some(step))
            {
                last += 1;
            }
            // A pair stays a list unless its step is 1.
            if last - i == 1 && step != 1 {
                last = i;
            }
        }
        let end = frames[last];
        parts.push(match (last - i, step) {
            (0, _) => first.to_string(),
            (_, Some(1)) => format!("{first}-{end}"),
            (_, Some(s)) => format!("{first}-{end}x{s}"),
            _ => first.to_string(),
        });
        i = last + 1;
    }
    parts.join(",")
}

/// Writes a job file (a script, a template) as every nerfx output is written: whole or not at
/// all, never over a device or through a link's back.
pub fn write_job_file(path: &Path, text: &str) -> Result<()> {
    nerfx_core::write_file(path, text.as_bytes())
}

/// Removes what an earlier, killed attempt at writing `path` left beside it (see
/// [`task`]: a task alone writes the frames of its chunk).
pub fn remove_stale_temporaries(path: &Path) -> Result<usize> {
    nerfx_core::remove_stale_temporaries(path)
}

/// `text` quoted for a POSIX shell (single quotes; a quote inside becomes `'\''`), bare when
/// it holds nothing a shell treats specially.
pub fn shell_quote(text: &str) -> String {
    let plain = !text.is_empty()
        && text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
    if plain {
        text.to_string()
    } else {
        format!("'{}'", text.replace('\'', r"'\''"))
    }
}

/// A command line for a POSIX shell.
pub fn shell_line(program: &Path, args: &[String]) -> String {
    let mut words = vec![shell_quote(&program.display().to_string())];
    words.extend(args.iter().map(|a| shell_quote(a)));
    words.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_specs_read_back_as_the_frames() {
        for frames in [
            vec![1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12],
            vec![1, 3, 5, 7, 8],
            vec![10, 5, 1],
            vec![-3, -2, -1, 0],
            vec![1, 3],
            vec![1001],
            vec![1, 2, 4, 8, 16],
        ] {
            let spec = frame_spec(&frames);
            assert_eq!(parse_frames(&spec).unwrap(), frames, "{spec}");
        }
        assert_eq!(frame_spec(&[1, 3]), "1,3");
        assert_eq!(frame_spec(&[1, 2]), "1-2");
    }

    #[test]
    fn shell_quoting() {
        assert_eq!(shell_quote("/a/b.exr"), "/a/b.exr");
        assert_eq!(shell_quote("out/comp.####.exr"), "'out/comp.####.exr'");
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
        assert_eq!(shell_quote(""), "''");
    }

    #[test]
    fn a_job_needs_numbered_outputs_existing_inputs_and_chunks() {
        let dir = tempfile::tempdir().unwrap();
        let scene = dir.path().join("scene.json");
        std::fs::write(&scene, "{}").unwrap();
        let out = dir.path().join("out/comp.####.exr");
        let job = FarmJob::new(std::slice::from_ref(&scene), "1-10", 4, &out, 1).unwrap();
        assert_eq!(job.name, "nerfx-comp");
        assert_eq!(
            job.chunks(),
            [&[1, 2, 3, 4][..], &[5, 6, 7, 8][..], &[9, 10][..]]
        );
        let e = |r: Result<FarmJob>| r.unwrap_err().to_string();
        let bad = FarmJob::new(
            std::slice::from_ref(&scene),
            "1-10",
            4,
            &dir.path().join("comp.exr"),
            1,
        );
        assert!(e(bad).contains("####"));
        assert!(e(FarmJob::new(
            std::slice::from_ref(&scene),
            "1-10",
            0,
            &out,
            1
        ))
        .contains("--chunk"));
        let missing = [dir.path().join("nope.json")];
        assert!(e(FarmJob::new(&missing, "1-10", 4, &out, 1)).contains("nope.json"));
        assert!(e(FarmJob::new(
            std::slice::from_ref(&scene),
            "1-10",
            4,
            &out,
            0
        ))
        .contains("--split-frame"));
    }

    #[test]
    fn a_job_is_checked_against_its_shot() {
        let dir = tempfile::tempdir().unwrap();
        let (scene, shot) = (dir.path().join("scene.json"), dir.path().join("shot.json"));
        nerfx_core::demo::scene_desc().write(&scene).unwrap();
        nerfx_core::demo::shot(32, 40).write(&shot).unwrap();
        let inputs = [scene, shot];
        let out = dir.path().join("f.####.exr");
        let job = |frames: &str, split| FarmJob::new(&inputs, frames, 4, &out, split).unwrap();
        job("1001-1024", 3).check().unwrap();
        let e = job("1001-1025", 1).check().unwrap_err().to_string();
        assert!(e.contains("1025"), "{e}");
        let e = job("1001", 4).check().unwrap_err().to_string();
        assert!(e.contains("--split-frame 4"), "{e}");
    }
}
