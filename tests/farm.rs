//! Farm jobs run on the real engines: a one-machine Slurm cluster (Debian's `slurm-wlm` and
//! `munge`, started here as root in a temporary folder and stopped at the end, failed tests
//! included), `openjd run` (PyPI's `openjd-cli`) and PyOutline (PyPI's `opencue-pyoutline`),
//! each frame checked pixel for pixel against the same frames rendered by one local
//! `nerfx render`. Also: a split frame assembles bit for bit, a task killed mid-frame runs
//! again leaving no partial file, and a bad scene fails at once with the no-retry status.

mod common_ofx;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use nerfx_core::image::{read_exr_channels, read_exr_image, Plane};

const FRAMES: &str = "1001-1012";
const WIDTH: u32 = 40;
const HEIGHT: u32 = 36;

fn nerfx() -> Command {
    Command::new(env!("CARGO_BIN_EXE_nerfx"))
}

fn run(command: &mut Command) -> Output {
    let out = command.output().expect("the command runs");
    assert!(
        out.status.success(),
        "{command:?} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The demo's scene and shot, written to `dir`.
fn scene_and_shot(dir: &Path) -> (PathBuf, PathBuf) {
    let (scene, shot) = (dir.join("scene.json"), dir.join("shot.json"));
    nerfx_core::demo::scene_desc().write(&scene).unwrap();
    nerfx_core::demo::shot(WIDTH, HEIGHT).write(&shot).unwrap();
    (scene, shot)
}

/// The frames rendered by one local `nerfx render`, the reference every engine must match.
fn local_render(scene: &Path, shot: &Path, dir: &Path) -> PathBuf {
    let pattern = dir.join("local/f.####.exr");
    run(nerfx()
        .arg("render")
        .args([scene, shot])
        .args(["--frames", FRAMES, "--quality", "draft", "-o"])
        .arg(&pattern));
    pattern
}

fn frame(pattern: &Path, frame: i64) -> PathBuf {
    nerfx::frames::frame_path(pattern, frame, true)
}

fn channels(path: &Path) -> Vec<(String, Plane)> {
    let mut c = read_exr_channels(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    c.sort_by(|a, b| a.0.cmp(&b.0));
    c
}

/// The EXRs at `got` and `want` hold the same image: every channel bit for bit and the same
/// header entries (OpenEXR leaves the order of a header's attributes free, and the writer
/// stores nerfx's own entries in no fixed order).
fn assert_same_image(got: &Path, want: &Path, what: &str) {
    let read = |p: &Path| read_exr_image(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let ((mut a, header_a), (mut b, header_b)) = (read(got), read(want));
    a.sort_by(|x, y| x.0.cmp(&y.0));
    b.sort_by(|x, y| x.0.cmp(&y.0));
    assert_eq!(header_a, header_b, "{what}: header");
    let bits = |c: &[(String, Plane)]| {
        c.iter()
            .map(|(n, p)| {
                (
                    n.clone(),
                    p.width,
                    p.height,
                    p.data.iter().map(|v| v.to_bits()).collect(),
                )
            })
            .collect::<Vec<(String, u32, u32, Vec<u32>)>>()
    };
    assert!(bits(&a) == bits(&b), "{what}: the channels differ");
}

/// Every frame of `pattern` equals the local render's, every channel bit for bit.
fn assert_frames_match(pattern: &Path, reference: &Path) {
    for f in 1001..=1012 {
        let (got, want) = (channels(&frame(pattern, f)), channels(&frame(reference, f)));
        assert_eq!(got.len(), want.len(), "frame {f}: channels");
        assert!(!got.is_empty());
        for ((name, a), (wname, b)) in got.iter().zip(&want) {
            assert_eq!(name, wname, "frame {f}");
            assert_eq!((a.width, a.height), (b.width, b.height), "frame {f} {name}");
            let same = a
                .data
                .iter()
                .zip(&b.data)
                .all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(
                same,
                "frame {f}: channel {name} differs from the local render"
            );
        }
    }
}

/// A one-node Slurm cluster in a temporary folder: its own munge key and socket, its own
/// ports and state, stopped (and its folder removed) when dropped.
struct Cluster {
    dir: tempfile::TempDir,
    conf: PathBuf,
    daemons: Vec<Child>,
}

impl Cluster {
    fn start() -> Cluster {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        for sub in ["munge", "state", "spool", "log"] {
            std::fs::create_dir(root.join(sub)).unwrap();
        }
        let key: Vec<u8> = (0..1024u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8 ^ std::process::id() as u8)
            .collect();
        let key_file = root.join("munge/key");
        std::fs::write(&key_file, key).unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&key_file, std::fs::Permissions::from_mode(0o600)).unwrap();
        std::fs::set_permissions(root.join("munge"), std::fs::Permissions::from_mode(0o700))
            .unwrap();
        let conf = dir.path().join("slurm.conf");
        let mut cluster = Cluster {
            dir,
            conf,
            daemons: Vec::new(),
        };
        let root = cluster.dir.path().to_path_buf();
        let socket = root.join("munge/socket");
        let munged = Command::new("munged")
            .args(["--foreground", "--force"])
            .arg(format!("--socket={}", socket.display()))
            .arg(format!("--key-file={}", key_file.display()))
            .arg(format!("--log-file={}", root.join("munge/log").display()))
            .arg(format!("--pid-file={}", root.join("munge/pid").display()))
            .arg(format!("--seed-file={}", root.join("munge/seed").display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("munged runs (apt-get install munge)");
        cluster.daemons.push(munged);
        wait_for("munged's socket", || socket.exists());

        let host = String::from_utf8(run(Command::new("hostname").arg("-s")).stdout)
            .unwrap()
            .trim()
            .to_string();
        let port = || {
            std::net::TcpListener::bind("127.0.0.1:0")
                .and_then(|l| l.local_addr())
                .map(|a| a.port())
                .unwrap()
        };
        let (ctld_port, slurmd_port) = (port(), port());
        let r = root.display();
        let conf = format!(
            "ClusterName=nerfxtest\n\
             SlurmctldHost={host}\n\
             SlurmUser=root\n\
             SlurmdUser=root\n\
             SlurmctldPort={ctld_port}\n\
             SlurmdPort={slurmd_port}\n\
             AuthType=auth/munge\n\
             AuthInfo=socket={r}/munge/socket,cred_expire=5\n\
             CredType=cred/munge\n\
             StateSaveLocation={r}/state\n\
             SlurmdSpoolDir={r}/spool\n\
             SlurmctldPidFile={r}/slurmctld.pid\n\
             SlurmdPidFile={r}/slurmd.pid\n\
             SlurmctldLogFile={r}/log/slurmctld.log\n\
             SlurmdLogFile={r}/log/slurmd.log\n\
             ProctrackType=proctrack/linuxproc\n\
             TaskPlugin=task/none\n\
             SelectType=select/cons_tres\n\
             SelectTypeParameters=CR_Core\n\
             SchedulerParameters=sched_interval=1,bf_interval=1\n\
             ReturnToService=2\n\
             MpiDefault=none\n\
             JobAcctGatherType=jobacct_gather/none\n\
             AccountingStorageType=accounting_storage/none\n\
             MinJobAge=600\n\
             KillWait=2\n\
             NodeName={host} CPUs=2 State=UNKNOWN\n\
             PartitionName=main Nodes={host} Default=YES MaxTime=INFINITE State=UP\n"
        );
        let conf_file = cluster.conf.clone();
        std::fs::write(&conf_file, conf).unwrap();
        for daemon in [&["slurmctld", "-D", "-i"][..], &["slurmd", "-D"][..]] {
            let child = Command::new(daemon[0])
                .args(&daemon[1..])
                .arg("-f")
                .arg(&conf_file)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("the Slurm daemons run (apt-get install slurm-wlm)");
            cluster.daemons.push(child);
        }
        wait_for("the node to be idle", || {
            cluster
                .command("sinfo")
                .args(["-h", "-o", "%T"])
                .output()
                .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "idle")
        });
        cluster
    }

    /// `program` run against this cluster (`SLURM_CONF`; what it runs inherits it).
    fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut command = Command::new(program);
        command.env("SLURM_CONF", &self.conf);
        command
    }

    /// Waits until none of `jobs` is queued or running.
    fn wait(&self, jobs: &[&str]) {
        wait_for("the jobs to end", || {
            let out = self
                .command("squeue")
                .args(["-h", "-o", "%i", "-j", &jobs.join(",")])
                .output()
                .unwrap();
            out.status.success() && out.stdout.iter().all(u8::is_ascii_whitespace)
        });
    }

    /// `scontrol show job` of `job` (each array task's record).
    fn show(&self, job: &str) -> String {
        String::from_utf8(run(self.command("scontrol").args(["show", "job", job])).stdout).unwrap()
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join("log/slurmctld.log")).unwrap_or_default()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        // A check that failed may leave jobs running: cancel them (every job of this cluster)
        // and give their tasks a moment to end before the daemons go.
        if self.daemons.len() == 3 {
            let _ = self.command("scancel").args(["--user", "root"]).output();
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(5) {
                let queued = self.command("squeue").args(["-h", "-o", "%i"]).output();
                if queued.map_or(true, |o| o.stdout.iter().all(u8::is_ascii_whitespace)) {
                    break;
                }
                std::thread::sleep(Duration::from_millis(100));
            }
        }
        // slurmd, then slurmctld, then munged.
        for child in self.daemons.iter_mut().rev() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

fn wait_for(what: &str, mut done: impl FnMut() -> bool) {
    let start = Instant::now();
    while !done() {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "timed out waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// The job id on the last line, `submitted job <id>`.
fn submitted(out: &Output) -> String {
    let text = String::from_utf8_lossy(&out.stdout);
    let last = text.lines().last().unwrap_or_default();
    last.strip_prefix("submitted job ")
        .unwrap_or_else(|| panic!("last line is not `submitted job <id>`:\n{text}"))
        .to_string()
}

/// One cluster for every Slurm check: starting it is most of the cost. Its jobs: 12 frames in
/// chunks of 4; the same split in three stripes; a task failing transiently once; a task
/// killed with SIGKILL mid-frame; a bad scene.
#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn slurm_runs_chunks_split_frames_retries_and_refuses_bad_scenes() {
    let work = tempfile::tempdir().unwrap();
    let (scene, shot) = scene_and_shot(work.path());
    let reference = local_render(&scene, &shot, work.path());
    let cluster = Cluster::start();
    let submit = |pattern: &Path, extra: &[&str], program: Option<&Path>| {
        let mut command = cluster.command(env!("CARGO_BIN_EXE_nerfx"));
        command
            .args(["farm", "slurm"])
            .args([&scene, &shot])
            .args([
                "--frames", FRAMES, "--chunk", "4", "--cpus", "1", "--submit", "-o",
            ])
            .arg(pattern)
            .args(extra);
        if let Some(program) = program {
            command.arg("--program").arg(program);
        }
        command.args(["--", "--quality", "draft"]);
        submitted(&run(&mut command))
    };

    // A task whose nerfx is killed with SIGKILL mid-frame: larger frames, so that the kill
    // lands inside the second; the program records its pid (and execs nerfx).
    let big_shot = work.path().join("big_shot.json");
    nerfx_core::demo::shot(960, 540).write(&big_shot).unwrap();
    let recorder = work.path().join("record-pid.sh");
    std::fs::write(
        &recorder,
        format!(
            "#!/bin/sh
echo $$ > {}/attempt-${{SLURM_RESTART_COUNT:-0}}.pid
exec {} \"$@\"\n",
            work.path().display(),
            env!("CARGO_BIN_EXE_nerfx")
        ),
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&recorder, std::fs::Permissions::from_mode(0o755)).unwrap();
    let killed = work.path().join("killed/f.####.exr");
    let killed_job = submitted(&run(cluster
        .command(env!("CARGO_BIN_EXE_nerfx"))
        .args(["farm", "slurm"])
        .args([&scene, &big_shot])
        .args([
            "--frames",
            "1001-1004",
            "--chunk",
            "4",
            "--cpus",
            "1",
            "--submit",
            "-o",
        ])
        .arg(&killed)
        .arg("--program")
        .arg(&recorder)
        .args(["--", "--quality", "draft"])));

    // 12 frames in chunks of 4: three array tasks, each frame the local render's.
    let whole = work.path().join("slurm/f.####.exr");
    let job = submit(&whole, &[], None);
    // A frame split in three stripes: a render array of 12 tasks, a joining array after it.
    let split = work.path().join("split/f.####.exr");
    let joined = submit(&split, &["--split-frame", "3"], None);
    // A task whose first attempt fails transiently (exit 75) is requeued and then succeeds.
    let flaky = work.path().join("flaky.sh");
    std::fs::write(
        &flaky,
        format!(
            "#!/bin/sh\n[ \"${{SLURM_RESTART_COUNT:-0}}\" = 0 ] && [ \"$SLURM_ARRAY_TASK_ID\" = 1 ] \
             && exit 75\nexec {} \"$@\"\n",
            env!("CARGO_BIN_EXE_nerfx")
        ),
    )
    .unwrap();
    std::fs::set_permissions(&flaky, std::fs::Permissions::from_mode(0o755)).unwrap();
    let retried = work.path().join("retried/f.####.exr");
    let retry_job = submit(&retried, &[], Some(&flaky));
    // A bad scene (its splat file is not a PLY; the job is checked, the file only read when
    // a task renders): the task ends at once with status 2, and is not requeued.
    let bad = work.path().join("bad.json");
    std::fs::write(work.path().join("bad.ply"), "not a ply\n").unwrap();
    std::fs::write(
        &bad,
        "{\"instances\": [{\"name\": \"scan\", \"field\": {\"splats\": {\"path\": \"bad.ply\"}}}]}",
    )
    .unwrap();
    let bad_out = run(cluster
        .command(env!("CARGO_BIN_EXE_nerfx"))
        .args(["farm", "slurm"])
        .args([&bad, &shot])
        .args(["--frames", "1001-1004", "--chunk", "4", "--submit", "-o"])
        .arg(work.path().join("bad/f.####.exr")));
    let bad_job = submitted(&bad_out);

    // Killed once its first frame is written, while it renders the second.
    let start = Instant::now();
    while !frame(&killed, 1001).exists() {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the job to kill never began"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    let pid_file = work.path().join("attempt-0.pid");
    let pid = std::fs::read_to_string(&pid_file).unwrap();
    let first_written = std::fs::metadata(frame(&killed, 1001))
        .unwrap()
        .modified()
        .unwrap();
    run(Command::new("kill").args(["-KILL", pid.trim()]));

    cluster.wait(&[&job, &joined, &retry_job, &bad_job, &killed_job]);
    let log = cluster.log();
    assert_frames_match(&whole, &reference);
    assert_frames_match(&split, &reference);
    assert_frames_match(&retried, &reference);
    let stripes = std::fs::read_dir(split.parent().unwrap())
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .contains("stripe")
        })
        .count();
    assert_eq!(stripes, 0, "the stripes are removed once joined");
    let retry = cluster.show(&format!("{retry_job}_1"));
    assert!(retry.contains("Restarts=1"), "{retry}\n{log}");
    // Run again by Slurm: the finished frame kept, the rest rendered, nothing partial left.
    let rerun = cluster.show(&format!("{killed_job}_0"));
    assert!(
        rerun.contains("Restarts=1") && rerun.contains("JobState=COMPLETED"),
        "{rerun}"
    );
    let kept = std::fs::metadata(frame(&killed, 1001))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(
        kept, first_written,
        "the frame finished before the kill is not redone"
    );
    let mut left: Vec<String> = std::fs::read_dir(killed.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(
        left,
        [
            "f.1001.exr",
            "f.1002.exr",
            "f.1003.exr",
            "f.1004.exr",
            "logs"
        ]
    );
    for f in 1001..=1004 {
        assert_eq!(
            channels(&frame(&killed, f)).len(),
            7,
            "frame {f} reads back whole"
        );
    }
    let failed = cluster.show(&bad_job);
    assert!(
        failed.contains("JobState=FAILED") && failed.contains("ExitCode=2:0"),
        "{failed}"
    );
    assert!(failed.contains("Restarts=0"), "{failed}");
    let logs = work.path().join("bad/logs");
    let text: String = std::fs::read_dir(&logs)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "log"))
        .filter_map(|p| std::fs::read_to_string(p).ok())
        .collect();
    assert!(
        text.contains("bad.ply"),
        "the task's log names the file:\n{text}"
    );
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn openjd_runs_the_template_and_its_split_frames() {
    let work = tempfile::tempdir().unwrap();
    let (scene, shot) = scene_and_shot(work.path());
    let reference = local_render(&scene, &shot, work.path());
    for (name, split) in [("whole", "1"), ("split", "2")] {
        let template = work.path().join(format!("{name}.yaml"));
        let pattern = work.path().join(format!("{name}/f.####.exr"));
        let bundle = work.path().join(format!("{name}-bundle"));
        run(nerfx()
            .args(["farm", "openjd"])
            .args([&scene, &shot])
            .args([
                "--frames",
                FRAMES,
                "--chunk",
                "4",
                "--cpus",
                "1",
                "--split-frame",
                split,
            ])
            .arg("--template")
            .arg(&template)
            .arg("--bundle")
            .arg(&bundle)
            .arg("-o")
            .arg(&pattern)
            .args(["--", "--quality", "draft"]));
        // openjd makes its session folders under the temp folder: this test's own.
        let openjd = || {
            let mut c = Command::new("openjd");
            c.env("TMPDIR", work.path());
            c
        };
        run(openjd().arg("check").arg(&template));
        run(openjd().arg("check").arg(bundle.join("template.yaml")));
        for file in [
            "template.yaml",
            "parameter_values.yaml",
            "asset_references.yaml",
        ] {
            assert!(bundle.join(file).is_file(), "{file}");
        }
        let step = if split == "1" { "Render" } else { "Assemble" };
        let values = template.with_file_name(format!("{name}.parameters.yaml"));
        let out = run(openjd()
            .arg("run")
            .arg(&template)
            .arg("-p")
            .arg(format!("file://{}", values.display()))
            .args(["--step", step, "--run-dependencies"]));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("openjd_progress"), "{text}");
        assert_frames_match(&pattern, &reference);
    }
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn pyoutline_loads_and_serialises_the_script() {
    let work = tempfile::tempdir().unwrap();
    let (scene, shot) = scene_and_shot(work.path());
    let script = work.path().join("job.outline");
    run(nerfx()
        .args(["farm", "opencue"])
        .args([&scene, &shot])
        .args([
            "--frames",
            "1001-1012x2",
            "--chunk",
            "3",
            "--split-frame",
            "2",
            "--script",
        ])
        .arg(&script)
        .arg("-o")
        .arg(work.path().join("out/f.####.exr")));
    let loader = "import sys\n\
                  from outline import load_outline, cuerun\n\
                  ol = load_outline(sys.argv[1])\n\
                  print(cuerun.OutlineLauncher(ol).serialize(use_pycuerun=False))\n";
    let out = run(Command::new("python3").args(["-c", loader]).arg(&script));
    let spec = String::from_utf8_lossy(&out.stdout);
    for want in [
        "<job name=\"nerfx-f\">",
        "<layer name=\"render_stripe1\" type=\"Render\">",
        "<layer name=\"assemble\" type=\"Render\">",
        "<range>1001-1011x2</range><chunk>3</chunk>",
        "--frames #FRAME_START#-#FRAME_END#x2",
        "--stripe 2/2",
        "<depend type=\"FRAME_BY_FRAME\" anyframe=\"False\"><depjob>nerfx-f</depjob>\
         <deplayer>assemble</deplayer><onjob>nerfx-f</onjob><onlayer>render_stripe2</onlayer>",
    ] {
        assert!(spec.contains(want), "{want} not in\n{spec}");
    }
}

#[test]
fn a_task_killed_mid_frame_reruns_without_partial_files() {
    let work = tempfile::tempdir().unwrap();
    let (scene, shot) = scene_and_shot(work.path());
    // Large enough frames that the kill lands inside one.
    let big = nerfx_core::demo::shot(480, 270);
    big.write(&shot).unwrap();
    let pattern = work.path().join("out/f.####.exr");
    let render = |frames: &str| {
        let mut c = nerfx();
        c.arg("render")
            .args([&scene, &shot])
            .args(["--frames", frames, "--quality", "draft", "--resume", "-o"])
            .arg(&pattern);
        c
    };
    let mut child = render("1001-1004").stdout(Stdio::piped()).spawn().unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    assert!(first.starts_with("frame 1001 →"), "{first}");
    // Killed while it renders frame 1002.
    child.kill().unwrap();
    child.wait().unwrap();
    let names = || {
        let mut n: Vec<String> = std::fs::read_dir(pattern.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        n.sort();
        n
    };
    // No frame under its own name but the finished one (a kill during a write may leave a
    // hidden temporary, which the rerun removes).
    let visible: Vec<String> = names()
        .into_iter()
        .filter(|n| !n.starts_with('.'))
        .collect();
    assert_eq!(visible, ["f.1001.exr"], "no partial frame");
    let kept = std::fs::metadata(frame(&pattern, 1001))
        .unwrap()
        .modified()
        .unwrap();
    let before = std::fs::read(frame(&pattern, 1001)).unwrap();
    // What a kill during the write leaves beside a frame.
    std::fs::write(
        pattern.with_file_name(".f.1002.exr.999999.0.partial"),
        b"half",
    )
    .unwrap();
    let out = run(&mut render("1001-1004"));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("frame 1001:") && text.contains("already whole"),
        "{text}"
    );
    assert_eq!(
        names(),
        ["f.1001.exr", "f.1002.exr", "f.1003.exr", "f.1004.exr"]
    );
    let after = std::fs::metadata(frame(&pattern, 1001))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(kept, after, "the finished frame is not rendered again");
    assert_eq!(before, std::fs::read(frame(&pattern, 1001)).unwrap());
    // The resumed frames are those one run renders.
    let fresh = work.path().join("fresh/f.####.exr");
    run(nerfx()
        .arg("render")
        .args([&scene, &shot])
        .args(["--frames", "1002", "--quality", "draft", "-o"])
        .arg(&fresh));
    assert_eq!(
        channels(&frame(&fresh, 1002)),
        channels(&frame(&pattern, 1002))
    );
}

#[test]
fn a_bad_scene_exits_with_the_no_retry_status_and_a_split_frame_is_the_whole_frame() {
    let work = tempfile::tempdir().unwrap();
    let (scene, shot) = scene_and_shot(work.path());
    let bad = work.path().join("bad.json");
    std::fs::write(&bad, "{ not json").unwrap();
    let out = nerfx()
        .arg("render")
        .args([&bad, &shot])
        .args(["--frames", "1001", "-o"])
        .arg(work.path().join("x.####.exr"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("bad.json"));
    // Every pass and the Cryptomatte layers and manifest, stripes of uneven height
    // included: 36 rows of 16-pixel tiles in 3 stripes.
    let whole = work.path().join("whole/f.####.exr");
    run(nerfx()
        .arg("render")
        .args([&scene, &shot])
        .args([
            "--frames",
            "1005",
            "--quality",
            "draft",
            "--cryptomatte",
            "-o",
        ])
        .arg(&whole));
    let split = work.path().join("split/f.####.exr");
    for k in 1..=3 {
        run(nerfx()
            .arg("render")
            .args([&scene, &shot])
            .args(["--frames", "1005", "--quality", "draft", "--cryptomatte"])
            .arg("--stripe")
            .arg(format!("{k}/3"))
            .arg("-o")
            .arg(&split));
    }
    run(nerfx()
        .args(["assemble", "--frames", "1005", "--split-frame", "3", "-o"])
        .arg(&split));
    assert_same_image(
        &frame(&split, 1005),
        &frame(&whole, 1005),
        "the assembled file is the whole-frame render's",
    );
    // Seven passes and three layers of two ranks each.
    let names: Vec<String> = channels(&frame(&split, 1005))
        .into_iter()
        .map(|(n, _)| n)
        .collect();
    assert_eq!(names.len(), 7 + 3 * 4, "{names:?}");
    assert!(names.contains(&"CryptoObject02.A".to_string()), "{names:?}");
    let (_, header) = read_exr_image(&frame(&split, 1005)).unwrap();
    assert!(
        header
            .entries
            .iter()
            .any(|(k, v)| k.ends_with("/manifest") && v.starts_with('{')),
        "{:?}",
        header.entries
    );
}

#[test]
fn a_graph_in_stripes_assembles_to_the_whole_frame_every_layer() {
    let work = tempfile::tempdir().unwrap();
    let graph = nerfx_graph::demo::write_graph(work.path(), WIDTH, HEIGHT).unwrap();
    let bundle = common_ofx::bundle();
    let render = |pattern: &Path, stripe: Option<String>| {
        let mut c = nerfx();
        c.arg("render")
            .arg(&graph)
            .args(["--frames", "1003", "--cryptomatte", "--bundle"])
            .arg(&bundle)
            .arg("-o")
            .arg(pattern);
        if let Some(stripe) = stripe {
            c.args(["--stripe", &stripe]);
        }
        run(&mut c);
    };
    let whole = work.path().join("whole/comp.####.exr");
    render(&whole, None);
    let split = work.path().join("split/comp.####.exr");
    for k in 1..=3 {
        render(&split, Some(format!("{k}/3")));
    }
    run(nerfx()
        .args(["assemble", "--frames", "1003", "--split-frame", "3", "-o"])
        .arg(&split));
    assert_same_image(
        &frame(&split, 1003),
        &frame(&whole, 1003),
        "the assembled graph frame is the whole-frame render's",
    );
    let names: Vec<String> = channels(&frame(&split, 1003))
        .into_iter()
        .map(|(n, _)| n)
        .collect();
    assert!(names.iter().any(|n| n.starts_with("object.")), "{names:?}");
    assert!(names.iter().any(|n| n.starts_with("shadow.")), "{names:?}");
    // --cryptomatte: every NeRF Render the output needs.
    assert!(names.iter().any(|n| n == "CryptoObject00.R"), "{names:?}");
}
