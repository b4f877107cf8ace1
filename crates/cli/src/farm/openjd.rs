//! Open Job Description (`jobtemplate-2023-09`): a job template whose step `Render` takes
//! its frames a chunk at a time (the `TASK_CHUNKING` extension's `CHUNK[INT]` task
//! parameter), and with split frames a stripe per task and a second step `Assemble`, which
//! depends on `Render`, joining the stripes. `openjd run` runs it on one machine; AWS Deadline
//! Cloud takes it as a job bundle ([`write_bundle`]: the template, `parameter_values.yaml`
//! and `asset_references.yaml`).
//!
//! Tasks report progress with `openjd_progress:` and `openjd_status:` lines. Open Job
//! Description has no retry of its own; Deadline Cloud retries a failed task up to the job's
//! `deadline:maxRetriesPerTask` ([`FarmJob::retries`]), whatever its exit status.

use std::path::Path;

use super::yaml::{map, s, strings, to_yaml, Node};
use super::{frame_spec, FarmJob, Progress};
use nerfx_core::error::{Error, Result};

/// The names of the job parameters holding the inputs, by how many there are.
fn input_names(count: usize) -> &'static [&'static str] {
    match count {
        1 => &["Graph"],
        _ => &["Scene", "Shot"],
    }
}

/// The job template for `job`, as YAML.
///
/// Errors: [`Error::Invalid`] when a passed-through render option holds `{{`, which Open Job
/// Description would read as an expression.
pub fn template(job: &FarmJob) -> Result<String> {
    if let Some(arg) = job.render_args.iter().find(|a| a.contains("{{")) {
        return Err(Error::invalid(
            format!("render option '{arg}'"),
            "holds '{{', which an Open Job Description template reads as an expression",
        ));
    }
    let names = input_names(job.inputs.len());
    // Paths have no defaults: Open Job Description reads a default path as relative to the
    // template's folder. Their values are in the parameter files (see [`path_values`]).
    let mut parameters = vec![map([
        ("name", s("Nerfx")),
        ("type", s("PATH")),
        ("objectType", s("FILE")),
        ("dataFlow", s("NONE")),
        (
            "description",
            s("The nerfx program, where every worker sees it."),
        ),
    ])];
    for name in names {
        parameters.push(map([
            ("name", s(*name)),
            ("type", s("PATH")),
            ("objectType", s("FILE")),
            ("dataFlow", s("IN")),
        ]));
    }
    let pattern = job
        .output
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    parameters.extend([
        map([
            ("name", s("OutputDir")),
            ("type", s("PATH")),
            ("objectType", s("DIRECTORY")),
            ("dataFlow", s("OUT")),
        ]),
        map([
            ("name", s("OutputPattern")),
            ("type", s("STRING")),
            (
                "description",
                s("The frames' file name; #### becomes the frame number."),
            ),
            ("default", s(pattern)),
        ]),
        map([
            ("name", s("Frames")),
            ("type", s("STRING")),
            ("default", s(frame_spec(&job.frames).replace('x', ":"))),
        ]),
        map([
            ("name", s("ChunkSize")),
            ("type", s("INT")),
            ("minValue", Node::Int(1)),
            ("default", Node::Int(job.chunk as i64)),
        ]),
    ]);

    // The task's arguments: the job's inputs and output become its parameters.
    let output = job.output.display().to_string();
    let as_parameters = |args: Vec<String>| -> Vec<String> {
        args.into_iter()
            .map(|arg| {
                if arg == output {
                    return "{{Param.OutputDir}}/{{Param.OutputPattern}}".to_string();
                }
                match job
                    .inputs
                    .iter()
                    .position(|p| p.display().to_string() == arg)
                {
                    Some(i) => format!("{{{{Param.{}}}}}", names[i]),
                    None => arg,
                }
            })
            .collect()
    };
    let frame_chunk = map([
        ("name", s("Frame")),
        ("type", s("CHUNK[INT]")),
        ("range", s("{{Param.Frames}}")),
        (
            "chunks",
            map([
                ("defaultTaskCount", s("{{Param.ChunkSize}}")),
                ("rangeConstraint", s("NONCONTIGUOUS")),
            ]),
        ),
    ]);
    let split = job.split;
    let stripe = format!("{{{{Task.Param.Stripe}}}}/{split}");
    let render_args = as_parameters(job.render_args(
        "{{Task.Param.Frame}}",
        (split > 1).then_some(stripe.as_str()),
        Progress::Openjd,
    ));
    let mut render_space = vec![("taskParameterDefinitions", {
        let mut defs = vec![frame_chunk.clone()];
        if split > 1 {
            defs.push(map([
                ("name", s("Stripe")),
                ("type", s("INT")),
                ("range", s(format!("1-{split}"))),
            ]));
        }
        Node::List(defs)
    })];
    if split > 1 {
        render_space.push(("combination", s("Frame * Stripe")));
    }
    let mut render = vec![
        ("name", s("Render")),
        ("parameterSpace", map(render_space)),
        ("script", run_script(&render_args)),
    ];
    let mut amounts = Vec::new();
    if let Some(cpus) = job.cpus {
        amounts.push(map([
            ("name", s("amount.worker.vcpu")),
            ("min", Node::Int(i64::from(cpus))),
        ]));
    }
    if let Some(mib) = job.memory_mib {
        amounts.push(map([
            ("name", s("amount.worker.memory")),
            ("min", Node::Int(mib.min(i64::MAX as u64) as i64)),
        ]));
    }
    let host = (!amounts.is_empty()).then(|| map([("amounts", Node::List(amounts))]));
    if let Some(host) = &host {
        render.push(("hostRequirements", host.clone()));
    }
    let mut steps = vec![map(render)];
    if split > 1 {
        let args = as_parameters(job.assemble_args("{{Task.Param.Frame}}", Progress::Openjd));
        steps.push(map([
            ("name", s("Assemble")),
            (
                "dependencies",
                Node::List(vec![map([("dependsOn", s("Render"))])]),
            ),
            (
                "parameterSpace",
                map([("taskParameterDefinitions", Node::List(vec![frame_chunk]))]),
            ),
            ("script", run_script(&args)),
        ]));
    }
    let doc = map([
        ("specificationVersion", s("jobtemplate-2023-09")),
        ("extensions", strings(&["TASK_CHUNKING"])),
        ("name", s(job.name.clone())),
        ("parameterDefinitions", Node::List(parameters)),
        ("steps", Node::List(steps)),
    ]);
    Ok(format!(
        "# Written by `nerfx farm openjd`. Exit status 0: done; 2: bad input; 75: transient.\n{}",
        to_yaml(&doc)
    ))
}

/// The values of the template's path parameters, by name: the program, the inputs, the
/// output folder.
pub fn path_values(job: &FarmJob) -> Vec<(&'static str, String)> {
    let mut values = vec![("Nerfx", job.program.display().to_string())];
    let names = input_names(job.inputs.len());
    values.extend(
        names
            .iter()
            .zip(&job.inputs)
            .map(|(name, path)| (*name, path.display().to_string())),
    );
    values.push(("OutputDir", job.output_dir().display().to_string()));
    values
}

/// The path parameters' values as `openjd run -p file://FILE` reads them: a mapping of
/// names to values.
pub fn run_parameters(job: &FarmJob) -> String {
    let values = path_values(job);
    to_yaml(&map(values
        .iter()
        .map(|(name, value)| (*name, s(value.as_str())))))
}

/// Where [`run_parameters`] go beside the template at `template` (`job.yaml` →
/// `job.parameters.yaml`).
pub fn run_parameters_path(template: &Path) -> std::path::PathBuf {
    let stem = template
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    template.with_file_name(format!("{stem}.parameters.yaml"))
}

/// A step script running the nerfx program with `args`.
fn run_script(args: &[String]) -> Node {
    map([(
        "actions",
        map([(
            "onRun",
            map([("command", s("{{Param.Nerfx}}")), ("args", strings(args))]),
        )]),
    )])
}

/// Deadline Cloud's `parameter_values.yaml`: the job's retry and failure limits, and the
/// path parameters' values.
pub fn parameter_values(job: &FarmJob) -> String {
    let value = |name: &str, v: Node| map([("name", s(name)), ("value", v)]);
    let mut values = vec![
        value(
            "deadline:maxRetriesPerTask",
            Node::Int(i64::from(job.retries)),
        ),
        value("deadline:maxFailedTasksCount", Node::Int(1)),
    ];
    values.extend(
        path_values(job)
            .into_iter()
            .map(|(name, path)| value(name, s(path))),
    );
    let doc = map([("parameterValues", Node::List(values))]);
    to_yaml(&doc)
}

/// Deadline Cloud's `asset_references.yaml`: the inputs and what they read (a scene's field
/// files and run folders), and the output folder.
pub fn asset_references(job: &FarmJob) -> String {
    let shown = |p: &std::path::PathBuf| p.display().to_string();
    let (folders, files): (Vec<_>, Vec<_>) = job.sources.iter().partition(|p| p.is_dir());
    let mut inputs: Vec<String> = job.inputs.iter().map(shown).collect();
    inputs.extend(files.into_iter().map(shown));
    let folders: Vec<String> = folders.into_iter().map(shown).collect();
    let doc = map([(
        "assetReferences",
        map([
            (
                "inputs",
                map([
                    ("filenames", strings(&inputs)),
                    ("directories", strings(&folders)),
                ]),
            ),
            (
                "outputs",
                map([(
                    "directories",
                    strings(&[job.output_dir().display().to_string()]),
                )]),
            ),
            ("referencedPaths", Node::List(vec![])),
        ]),
    )]);
    to_yaml(&doc)
}

/// Writes `job` as a Deadline Cloud job bundle in `dir` (created when missing):
/// `template.yaml`, `parameter_values.yaml` and `asset_references.yaml`.
pub fn write_bundle(job: &FarmJob, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let files = [
        ("template.yaml", template(job)?),
        ("parameter_values.yaml", parameter_values(job)),
        ("asset_references.yaml", asset_references(job)),
    ];
    for (name, text) in files {
        nerfx_core::write_file(&dir.join(name), text.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job() -> FarmJob {
        FarmJob {
            name: "nerfx-comp".into(),
            program: "/opt/nerfx".into(),
            inputs: vec!["/show/scene.json".into(), "/show/shot.json".into()],
            output: "/show/out/comp.####.exr".into(),
            frames: (1..=12).step_by(2).collect(),
            chunk: 4,
            split: 1,
            render_args: vec!["--quality".into(), "draft".into()],
            cpus: Some(4),
            memory_mib: None,
            retries: 2,
            sources: vec![],
        }
    }

    #[test]
    fn the_template_names_its_parameters_and_chunks() {
        let t = template(&job()).unwrap();
        for line in [
            "specificationVersion: \"jobtemplate-2023-09\"",
            "- name: \"Scene\"",
            "  dataFlow: \"OUT\"",
            "  default: \"1-11:2\"",
            "  type: \"CHUNK[INT]\"",
            "    - \"{{Param.Scene}}\"",
            "    - \"{{Param.OutputDir}}/{{Param.OutputPattern}}\"",
            "    - \"{{Task.Param.Frame}}\"",
            "    - name: \"amount.worker.vcpu\"",
        ] {
            assert!(
                t.lines().any(|l| l.trim_start() == line.trim_start()),
                "{line} not in\n{t}"
            );
        }
        assert!(!t.contains("Assemble"));
        let split = template(&FarmJob { split: 4, ..job() }).unwrap();
        assert!(split.contains("combination: \"Frame * Stripe\""), "{split}");
        assert!(split.contains("\"{{Task.Param.Stripe}}/4\""), "{split}");
        assert!(split.contains("dependsOn: \"Render\""), "{split}");
        let bad = FarmJob {
            render_args: vec!["{{x}}".into()],
            ..job()
        };
        assert!(template(&bad).is_err());
        assert!(parameter_values(&job()).contains("deadline:maxRetriesPerTask"));
        assert!(parameter_values(&job()).contains("value: \"/show/scene.json\""));
        assert_eq!(
            run_parameters(&job()),
            "Nerfx: \"/opt/nerfx\"\nScene: \"/show/scene.json\"\nShot: \"/show/shot.json\"\n\
             OutputDir: \"/show/out\"\n"
        );
        assert!(asset_references(&job()).contains("- \"/show/out\""));
        let with_fields = FarmJob {
            sources: vec!["/show/fields/plant.ply".into()],
            ..job()
        };
        let refs = asset_references(&with_fields);
        assert!(refs.contains("  - \"/show/fields/plant.ply\""), "{refs}");
    }
}
