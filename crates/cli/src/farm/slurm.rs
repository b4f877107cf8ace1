//! Slurm: an `sbatch` job-array script, one array task per chunk (per chunk and stripe when
//! frames are split), and with split frames a second array, one task per chunk, that joins
//! the stripes once the first has finished (`--dependency=afterok`).
//!
//! A task that fails transiently (exit 75), or whose `nerfx` was killed by a signal (the
//! kernel's out-of-memory killer, a `kill -9`: the shell reports 128 + the signal), requeues
//! itself with `scontrol requeue`, at most [`FarmJob::retries`] times (Slurm's
//! `SLURM_RESTART_COUNT` counts them); the attempt that runs next resumes where the killed
//! one stopped. Any other failure, bad input above all, ends the task for good. `--requeue` also lets Slurm requeue a task whose node died.

use std::fmt::Write;
use std::path::{Path, PathBuf};

use super::{frame_spec, shell_quote, FarmJob, Progress};

/// What only Slurm needs to know.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SlurmOptions {
    /// `--partition`.
    pub partition: Option<String>,
    /// At most this many array tasks run at once (`--array=…%N`).
    pub max_running: Option<u32>,
    /// The folder of the tasks' logs (one per task, `<job>_<array job>_<task>.log`).
    pub log_dir: PathBuf,
}

/// Which array a script is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Array {
    /// The tasks that render (whole frames, or stripes).
    Render,
    /// The tasks that join stripes into frames.
    Assemble,
}

/// The `sbatch` script of `array` for `job`.
pub fn script(job: &FarmJob, options: &SlurmOptions, array: Array) -> String {
    let chunks = job.chunks();
    let stripes = job.split as usize;
    let tasks = match array {
        Array::Render if stripes > 1 => chunks.len() * stripes,
        _ => chunks.len(),
    };
    let name = match array {
        Array::Render => job.name.clone(),
        Array::Assemble => format!("{}-assemble", job.name),
    };
    let mut s = String::from("#!/bin/bash\n");
    let mut directive = |text: String| {
        let _ = writeln!(s, "#SBATCH {text}");
    };
    directive(format!("--job-name={}", shell_quote(&name)));
    let limit = options
        .max_running
        .map_or_else(String::new, |n| format!("%{n}"));
    directive(format!("--array=0-{}{limit}", tasks.saturating_sub(1)));
    let log = options.log_dir.join(format!("{name}_%A_%a.log"));
    directive(format!(
        "--output={}",
        shell_quote(&log.display().to_string())
    ));
    directive("--open-mode=append".into());
    directive("--requeue".into());
    directive("--ntasks=1".into());
    if let Some(cpus) = job.cpus {
        directive(format!("--cpus-per-task={cpus}"));
    }
    if let Some(mib) = job.memory_mib {
        directive(format!("--mem={mib}M"));
    }
    if let Some(partition) = &options.partition {
        directive(format!("--partition={}", shell_quote(partition)));
    }
    let _ = writeln!(
        s,
        "#\n# Written by `nerfx farm slurm`: {} frames in chunks of {}{}.\n\
         # Exit status 0: done; 2: bad input (not retried); 75 or killed by a signal: transient
         # (requeued, at most {} times).",
        job.frames.len(),
        job.chunk,
        if stripes > 1 {
            format!(", each frame in {stripes} stripes")
        } else {
            String::new()
        },
        job.retries
    );
    s.push_str("set -u\n");
    if let Some(cpus) = job.cpus {
        // nerfx renders on as many threads as the machine has cores unless told otherwise;
        // a task keeps to the CPUs it asked for, so tasks sharing a node do not oversubscribe.
        let _ = writeln!(s, "export RAYON_NUM_THREADS={cpus}");
    }
    let specs: Vec<String> = chunks.iter().map(|c| shell_quote(&frame_spec(c))).collect();
    let _ = writeln!(s, "chunks=({})", specs.join(" "));
    let program = &job.program;
    let command = match array {
        Array::Render if stripes > 1 => {
            let _ = writeln!(
                s,
                "frames=${{chunks[$((SLURM_ARRAY_TASK_ID / {stripes}))]}}\n\
                 stripe=$((SLURM_ARRAY_TASK_ID % {stripes} + 1))/{stripes}"
            );
            let args = job.render_args(FRAMES, Some(STRIPE), Progress::Plain);
            command_line(program, &args)
        }
        Array::Render => {
            s.push_str("frames=${chunks[$SLURM_ARRAY_TASK_ID]}\n");
            let args = job.render_args(FRAMES, None, Progress::Plain);
            command_line(program, &args)
        }
        Array::Assemble => {
            s.push_str("frames=${chunks[$SLURM_ARRAY_TASK_ID]}\n");
            let args = job.assemble_args(FRAMES, Progress::Plain);
            command_line(program, &args)
        }
    };
    let _ = writeln!(
        s,
        "{command}\n\
         status=$?\n\
         if {{ [ \"$status\" -eq 75 ] || [ \"$status\" -gt 128 ]; }} && \
         [ \"${{SLURM_RESTART_COUNT:-0}}\" -lt {retries} ]; then\n\
         \x20   echo \"nerfx: transient failure (exit $status): requeueing task $SLURM_ARRAY_TASK_ID\"\n\
         \x20   scontrol requeue \"${{SLURM_ARRAY_JOB_ID}}_${{SLURM_ARRAY_TASK_ID}}\"\n\
         fi\n\
         exit \"$status\"",
        retries = job.retries
    );
    s
}

/// Stand-ins for the task's frames and stripe in its arguments (no real argument holds a NUL).
const FRAMES: &str = "\0frames";
const STRIPE: &str = "\0stripe";

/// The task's command line: the stand-ins become the script's variables.
fn command_line(program: &Path, args: &[String]) -> String {
    let mut words = vec![shell_quote(&program.display().to_string())];
    words.extend(args.iter().map(|arg| match arg.as_str() {
        FRAMES => "\"$frames\"".to_string(),
        STRIPE => "\"$stripe\"".to_string(),
        other => shell_quote(other),
    }));
    words.join(" ")
}

/// Where the joining array's script goes, beside the rendering one (`job.sh` →
/// `job.assemble.sh`).
pub fn assemble_script_path(script: &Path) -> PathBuf {
    let stem = script
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match script.extension() {
        Some(ext) => format!("{stem}.assemble.{}", ext.to_string_lossy()),
        None => format!("{stem}.assemble"),
    };
    script.with_file_name(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(split: u32) -> FarmJob {
        FarmJob {
            name: "nerfx-comp".into(),
            program: "/opt/nerfx/bin/nerfx".into(),
            inputs: vec!["/show/scene.json".into(), "/show/shot one.json".into()],
            output: "/show/out/comp.####.exr".into(),
            frames: (1..=10).collect(),
            chunk: 4,
            split,
            render_args: vec!["--quality".into(), "draft".into()],
            cpus: Some(8),
            memory_mib: Some(16384),
            retries: 3,
            sources: vec![],
        }
    }

    #[test]
    fn a_script_has_one_task_per_chunk_and_requeues_only_transient_failures() {
        let options = SlurmOptions {
            partition: Some("render".into()),
            max_running: Some(5),
            log_dir: "/show/logs".into(),
        };
        let s = script(&job(1), &options, Array::Render);
        for line in [
            "#SBATCH --array=0-2%5",
            "#SBATCH --output=/show/logs/nerfx-comp_%A_%a.log",
            "#SBATCH --cpus-per-task=8",
            "export RAYON_NUM_THREADS=8",
            "#SBATCH --mem=16384M",
            "#SBATCH --partition=render",
            "chunks=(1-4 5-8 9-10)",
            "frames=${chunks[$SLURM_ARRAY_TASK_ID]}",
            "/opt/nerfx/bin/nerfx render /show/scene.json '/show/shot one.json' --frames \
             \"$frames\" -o '/show/out/comp.####.exr' --resume --progress plain --quality draft",
            "if { [ \"$status\" -eq 75 ] || [ \"$status\" -gt 128 ]; } && \
             [ \"${SLURM_RESTART_COUNT:-0}\" -lt 3 ]; then",
        ] {
            assert!(s.lines().any(|l| l == line), "{line} not in\n{s}");
        }
        let split = script(&job(3), &options, Array::Render);
        assert!(split.contains("#SBATCH --array=0-8%5"), "{split}");
        assert!(split.contains("--stripe \"$stripe\""), "{split}");
        let assemble = script(&job(3), &options, Array::Assemble);
        assert!(assemble.contains("#SBATCH --array=0-2%5"), "{assemble}");
        assert!(assemble.contains("assemble --frames \"$frames\" --split-frame 3"));
        assert_eq!(
            assemble_script_path(Path::new("/a/job.sh")),
            Path::new("/a/job.assemble.sh")
        );
    }
}
