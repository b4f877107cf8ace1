//! OpenCue: a PyOutline script with a `Shell` layer that renders its chunk, from
//! `#FRAME_START#` to `#FRAME_END#`, over the job's range; with split frames one such layer
//! per stripe, and a layer `assemble` that waits on each of them frame by frame and joins the
//! stripes. `pycuerun SCRIPT` submits it to a Cuebot (`--max-retries` sets how often a failed
//! frame runs again).
//!
//! OpenCue's frame ranges are one range with an optional step (`1001-1100x5`), so that is
//! what an OpenCue job takes.

use std::fmt::Write;

use super::{shell_quote, FarmJob, Progress};
use nerfx_core::error::{Error, Result};

/// A Python string literal (JSON's escapes are Python's).
fn py(text: &str) -> String {
    serde_json::Value::String(text.to_string()).to_string()
}

/// The job's frames as an OpenCue range (`first-last` or `first-lastxstep`), or an error
/// when they are not one.
fn cue_range(frames: &[i64]) -> Result<(String, i64)> {
    let (Some(&first), Some(&last)) = (frames.first(), frames.last()) else {
        return Err(Error::invalid("--frames", "no frame to render"));
    };
    let step = frames.get(1).map_or(1, |next| next - first);
    let even = step > 0 && frames.windows(2).all(|w| w[1] - w[0] == step);
    if !even {
        return Err(Error::invalid(
            "--frames",
            "an OpenCue layer's frames are one range with an optional step (1001-1100x5)",
        ));
    }
    Ok(match step {
        1 => (format!("{first}-{last}"), 1),
        _ => (format!("{first}-{last}x{step}"), step),
    })
}

/// The PyOutline script for `job`.
pub fn script(job: &FarmJob) -> Result<String> {
    let (range, step) = cue_range(&job.frames)?;
    let chunk_frames = match step {
        1 => "#FRAME_START#-#FRAME_END#".to_string(),
        s => format!("#FRAME_START#-#FRAME_END#x{s}"),
    };
    // PyOutline joins a command's words with spaces for the shell: each word is quoted.
    let command = |args: Vec<String>| {
        let mut words = vec![shell_quote(&job.program.display().to_string())];
        words.extend(args.iter().map(|a| match a.as_str() {
            a if a == chunk_frames => a.to_string(),
            a => shell_quote(a),
        }));
        format!(
            "[{}]",
            words.iter().map(|w| py(w)).collect::<Vec<_>>().join(", ")
        )
    };
    let mut resources = String::new();
    if let Some(cpus) = job.cpus {
        let _ = write!(resources, ", cores={cpus}");
    }
    if let Some(mib) = job.memory_mib {
        let _ = write!(resources, ", memory={}", py(&format!("{mib}m")));
    }
    let mut s = format!(
        "# Written by `nerfx farm opencue`: {} frames in chunks of {}. Submit with\n\
         #   pycuerun --max-retries {} THIS_FILE\n\
         # Exit status 0: done; 2: bad input; 75: transient.\n\
         from outline import current_outline\n\
         from outline.modules.shell import Shell\n\n\
         current_outline().set_name({})\n",
        job.frames.len(),
        job.chunk,
        job.retries,
        py(&job.name)
    );
    let layer = |s: &mut String, var: &str, name: &str, cmd: String| {
        let _ = writeln!(
            s,
            "{var} = Shell({}, command={cmd}, range={}, chunk={}{resources})",
            py(name),
            py(&range),
            job.chunk
        );
    };
    if job.split <= 1 {
        let args = job.render_args(&chunk_frames, None, Progress::Plain);
        layer(&mut s, "render", "render", command(args));
        return Ok(s);
    }
    for k in 1..=job.split {
        let stripe = format!("{k}/{}", job.split);
        let args = job.render_args(&chunk_frames, Some(&stripe), Progress::Plain);
        layer(
            &mut s,
            &format!("render_{k}"),
            &format!("render_stripe{k}"),
            command(args),
        );
    }
    let args = job.assemble_args(&chunk_frames, Progress::Plain);
    layer(&mut s, "assemble", "assemble", command(args));
    for k in 1..=job.split {
        let _ = writeln!(s, "assemble.depend_on(render_{k})");
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layers_render_their_chunk_and_assemble_waits_frame_by_frame() {
        let job = FarmJob {
            name: "nerfx-comp".into(),
            program: "/opt/nerfx".into(),
            inputs: vec!["/show/comp graph.json".into()],
            output: "/show/out/comp.####.exr".into(),
            frames: (1..=12).collect(),
            chunk: 4,
            split: 1,
            render_args: vec![],
            cpus: Some(2),
            memory_mib: Some(4096),
            retries: 2,
            sources: vec![],
        };
        let s = script(&job).unwrap();
        assert!(
            s.contains("range=\"1-12\", chunk=4, cores=2, memory=\"4096m\""),
            "{s}"
        );
        assert!(
            s.contains("\"'/show/comp graph.json'\", \"--frames\", \"#FRAME_START#-#FRAME_END#\""),
            "{s}"
        );
        let split = script(&FarmJob {
            split: 2,
            ..job.clone()
        })
        .unwrap();
        assert!(split.contains("assemble.depend_on(render_2)"), "{split}");
        let stepped = FarmJob {
            frames: vec![1, 3, 5],
            ..job.clone()
        };
        assert!(script(&stepped)
            .unwrap()
            .contains("#FRAME_START#-#FRAME_END#x2"));
        let uneven = FarmJob {
            frames: vec![1, 2, 5],
            ..job
        };
        assert!(script(&uneven).is_err());
    }
}
