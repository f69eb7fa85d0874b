//! `cargo xtask slurm-check`: the sharded evaluation of `docs/evaluation-protocol.md` on a
//! real Slurm cluster, a one-node one on this machine. Not part of CI (it installs Debian
//! packages and starts daemons); its transcript is in `docs/slurm-check.md`.
//!
//! 1. Installs Debian's `slurm-wlm` and `munge` when a program is missing (as root, or
//!    through sudo).
//! 2. Starts `munged`, `slurmctld` and `slurmd` in the foreground as children of this
//!    process, with a generated key, `slurm.conf` and state in a scratch folder (`--work`;
//!    nothing under `/etc` is read or written: the clients get `SLURM_CONF`), on ports
//!    16817/16818 of 127.0.0.1, without cgroups or systemd.
//! 3. Submits `bitt eval --preset tiny --scenes 4 --shard $SLURM_ARRAY_TASK_ID/4` as a 4-task
//!    job array running a copy of the release binary, cancels task 1 in the middle of its
//!    second scene result (after the first was written), resubmits that task alone and
//!    checks that it skipped the finished result.
//! 4. Runs `bitt eval-merge`, then the same evaluation in one process (own cache), and checks
//!    that every scene result, `results.json` and every contact sheet are identical,
//!    byte for byte, except the `seconds` fields (training wall times).
//!
//! The daemons are stopped (and leftover jobs cancelled) on every exit path but a kill of
//! this process itself; the next run stops daemons a killed run left (their pids are in the
//! scratch folder).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};

/// Shards of the job array (= array tasks).
const SHARDS: usize = 4;
/// The array task that is cancelled mid-run and resubmitted.
const CANCEL_TASK: usize = 1;
/// The evaluation every shard and the single-process run do (`--shard` / `--out` /
/// `--cache` added).
const EVAL_ARGS: [&str; 5] = ["eval", "--preset", "tiny", "--scenes", "4"];
/// The cluster's ports on 127.0.0.1 (not Slurm's defaults, so a real installation is left
/// alone).
const CTLD_PORT: u16 = 16817;
const SLURMD_PORT: u16 = 16818;
/// Marks a scratch folder as ours, so it may be wiped on the next run.
const MARKER: &str = ".bitt-slurm-check";

const USAGE: &str = "usage: cargo xtask slurm-check [--work DIR] [--bitt PATH] [--timeout-min N]";

struct Options {
    work: PathBuf,
    bitt: Option<PathBuf>,
    timeout: Duration,
}

fn parse(args: &[String]) -> Result<Options> {
    let mut o = Options {
        work: std::env::temp_dir().join("bitt-slurm-check"),
        bitt: None,
        timeout: Duration::from_secs(90 * 60),
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || {
            it.next()
                .with_context(|| format!("{a} needs a value; {USAGE}"))
        };
        match a.as_str() {
            "--work" => o.work = PathBuf::from(value()?),
            "--bitt" => o.bitt = Some(PathBuf::from(value()?)),
            "--timeout-min" => {
                let m: u64 = value()?.parse().context("--timeout-min takes minutes")?;
                o.timeout = Duration::from_secs(60 * m);
            }
            other => bail!("unknown argument `{other}`; {USAGE}"),
        }
    }
    if o.work.is_relative() {
        o.work = std::env::current_dir()?.join(&o.work);
    }
    Ok(o)
}

/// What the check did, printed as it goes and saved as `transcript.txt` in the scratch folder.
struct Transcript {
    text: String,
    started: Instant,
    file: PathBuf,
}

impl Transcript {
    fn say(&mut self, line: &str) {
        let line = format!("[{:6.1} s] {line}", self.started.elapsed().as_secs_f64());
        println!("{line}");
        self.text.push_str(&line);
        self.text.push('\n');
    }
    fn cmd(&mut self, line: &str) {
        self.say(&format!("$ {line}"));
    }
    fn out(&mut self, text: &str) {
        for l in text.lines() {
            println!("    {l}");
            let _ = writeln!(self.text, "    {l}");
        }
    }
    fn save(&self) {
        let _ = std::fs::write(&self.file, &self.text);
    }
}

/// `cargo xtask slurm-check`.
pub fn slurm_check(args: &[String]) -> Result<()> {
    let o = parse(args)?;
    let started = Instant::now();
    prepare_work(&o.work)?;
    let mut t = Transcript {
        text: String::new(),
        started,
        file: o.work.join("transcript.txt"),
    };
    let result = run(&o, &mut t);
    match &result {
        Ok(()) => t.say(&format!(
            "slurm-check PASSED in {:.1} min",
            started.elapsed().as_secs_f64() / 60.0
        )),
        Err(e) => t.say(&format!("slurm-check FAILED: {e:#}")),
    }
    t.say(&format!("transcript: {}", t.file.display()));
    t.save();
    result
}

/// Empties the scratch folder (only one of ours), stopping daemons a killed run left.
fn prepare_work(work: &Path) -> Result<()> {
    if work.exists() {
        if !work.join(MARKER).is_file() {
            let empty = std::fs::read_dir(work)
                .with_context(|| format!("reading {}", work.display()))?
                .next()
                .is_none();
            if !empty {
                bail!(
                    "{} exists and is not a slurm-check folder; give another --work",
                    work.display()
                );
            }
        }
        stop_stale_daemons(work);
        std::fs::remove_dir_all(work).with_context(|| format!("removing {}", work.display()))?;
    }
    for d in [
        "",
        "munge-key",
        "munge",
        "state",
        "spool",
        "log",
        "logs",
        "bin",
    ] {
        std::fs::create_dir_all(work.join(d))?;
    }
    std::fs::write(
        work.join(MARKER),
        "scratch folder of `cargo xtask slurm-check`\n",
    )?;
    // munged wants its key readable by its user alone and the socket's folder open to all.
    chmod(&work.join("munge-key"), "700")?;
    chmod(&work.join("munge"), "755")?;
    Ok(())
}

fn chmod(path: &Path, mode: &str) -> Result<()> {
    let status = Command::new("chmod").arg(mode).arg(path).status()?;
    crate::check(status, "chmod")
}

/// Stops the daemons whose pids a previous (killed) run wrote into `work/daemons.pid`, when
/// the process with that pid is still that daemon.
fn stop_stale_daemons(work: &Path) {
    let Ok(text) = std::fs::read_to_string(work.join("daemons.pid")) else {
        return;
    };
    for line in text.lines() {
        let Some((name, pid)) = line.split_once(' ') else {
            continue;
        };
        let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        let cmdline = String::from_utf8_lossy(&cmdline);
        if cmdline.contains(name) && cmdline.contains(&*work.to_string_lossy()) {
            println!("stopping {name} (pid {pid}) left by an earlier run");
            let _ = Command::new("kill").args(["-TERM", pid]).status();
            std::thread::sleep(Duration::from_secs(2));
            let _ = Command::new("kill").args(["-KILL", pid]).status();
        }
    }
}

/// Finds a program on `PATH` or in the sbin folders (which a non-root `PATH` may lack).
fn program(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin", "/sbin", "/usr/local/sbin"].map(PathBuf::from))
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

const PROGRAMS: [&str; 10] = [
    "munged",
    "munge",
    "slurmctld",
    "slurmd",
    "sbatch",
    "squeue",
    "scancel",
    "scontrol",
    "sinfo",
    "hostname",
];

fn install(t: &mut Transcript) -> Result<()> {
    let missing: Vec<&str> = PROGRAMS
        .into_iter()
        .filter(|p| program(p).is_none())
        .collect();
    if missing.is_empty() {
        t.say("slurm-wlm and munge are installed");
        return Ok(());
    }
    t.say(&format!(
        "missing {}: installing Debian's slurm-wlm and munge",
        missing.join(", ")
    ));
    let root = Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false);
    let as_root = |args: &[&str]| {
        let mut c = if root {
            Command::new(args[0])
        } else {
            let mut c = Command::new("sudo");
            c.arg(args[0]);
            c
        };
        c.args(&args[1..]).env("DEBIAN_FRONTEND", "noninteractive");
        c
    };
    t.cmd("apt-get update -qq");
    crate::check(
        as_root(&["apt-get", "update", "-qq"]).status()?,
        "apt-get update",
    )?;
    t.cmd("apt-get install -y -qq slurm-wlm munge");
    let status = as_root(&["apt-get", "install", "-y", "-qq", "slurm-wlm", "munge"])
        .stdout(Stdio::null())
        .status()?;
    crate::check(status, "apt-get install slurm-wlm munge")?;
    if let Some(p) = PROGRAMS.into_iter().find(|p| program(p).is_none()) {
        bail!("{p} is still missing after installing slurm-wlm and munge");
    }
    Ok(())
}

/// The one-node cluster: its daemons (children of this process) and the jobs submitted.
struct Cluster {
    work: PathBuf,
    conf: PathBuf,
    socket: PathBuf,
    daemons: Vec<(&'static str, Child)>,
    jobs: Vec<String>,
}

impl Cluster {
    fn start(work: &Path, t: &mut Transcript) -> Result<Cluster> {
        let mut c = Cluster {
            work: work.to_path_buf(),
            conf: work.join("slurm.conf"),
            socket: work.join("munge/munge.socket"),
            daemons: Vec::new(),
            jobs: Vec::new(),
        };
        // Started here so that `Drop` stops whatever did start when a later step fails.
        c.start_daemons(t)?;
        Ok(c)
    }

    fn start_daemons(&mut self, t: &mut Transcript) -> Result<()> {
        let work = self.work.clone();
        let version = capture(Command::new(need("slurmctld")?).arg("-V"))?;
        let munge_version = capture(Command::new(need("munged")?).arg("-V"))?;
        t.say(&format!(
            "{} / {}",
            version.trim(),
            munge_version.lines().next().unwrap_or("").trim()
        ));
        // munge: a fresh key and a private socket.
        let key = work.join("munge-key/munge.key");
        std::fs::write(&key, random_key()?)?;
        chmod(&key, "600")?;
        let mut munged = Command::new(need("munged")?);
        munged
            .args(["--foreground", "--force"])
            .arg(format!("--socket={}", self.socket.display()))
            .arg(format!("--key-file={}", key.display()))
            .arg(format!(
                "--pid-file={}",
                work.join("munge/munged.pid").display()
            ))
            .arg(format!(
                "--seed-file={}",
                work.join("munge-key/munged.seed").display()
            ));
        t.cmd(&format!(
            "munged --foreground --force --socket={} --key-file={} ...",
            self.socket.display(),
            key.display()
        ));
        self.spawn("munged", munged)?;
        self.wait_until("munged", Duration::from_secs(20), |c| {
            let mut m = Command::new(need("munge")?);
            m.arg("-n").arg("-S").arg(&c.socket);
            Ok(m.stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()?
                .success())
        })?;
        t.say("munged is up");

        // slurm.conf, from the node's own description (`slurmd -C`).
        let probe = capture(Command::new(need("slurmd")?).arg("-C"))?;
        let node_line = probe
            .lines()
            .find(|l| l.starts_with("NodeName="))
            .with_context(|| format!("slurmd -C printed no NodeName line:\n{probe}"))?;
        let field = |k: &str| {
            node_line
                .split_whitespace()
                .find_map(|f| f.strip_prefix(k).and_then(|v| v.strip_prefix('=')))
                .map(str::to_string)
        };
        let node = field("NodeName").context("slurmd -C: no NodeName")?;
        let hardware: Vec<String> = [
            "CPUs",
            "Boards",
            "SocketsPerBoard",
            "CoresPerSocket",
            "ThreadsPerCore",
        ]
        .iter()
        .filter_map(|k| field(k).map(|v| format!("{k}={v}")))
        .collect();
        let conf = slurm_conf(&work, &node, &hardware.join(" "), &self.socket);
        std::fs::write(&self.conf, &conf)?;
        std::fs::create_dir_all(work.join("spool"))?;
        t.say(&format!("{} (from `slurmd -C`):", self.conf.display()));
        t.out(&conf);

        let mut ctld = Command::new(need("slurmctld")?);
        ctld.args(["-D", "-i"]);
        t.cmd("slurmctld -D -i   # SLURM_CONF set, foreground, no saved state");
        self.spawn("slurmctld", ctld)?;
        self.wait_until("slurmctld", Duration::from_secs(60), |c| {
            let out = c.slurm("scontrol").arg("ping").output()?;
            Ok(String::from_utf8_lossy(&out.stdout).contains("is UP"))
        })?;
        let mut slurmd = Command::new(need("slurmd")?);
        slurmd.arg("-D");
        t.cmd("slurmd -D");
        self.spawn("slurmd", slurmd)?;
        self.wait_until("slurmd", Duration::from_secs(60), |c| {
            let out = c.slurm("sinfo").args(["-h", "-o", "%T"]).output()?;
            Ok(String::from_utf8_lossy(&out.stdout).trim() == "idle")
        })?;
        t.cmd("sinfo");
        t.out(&capture(&mut self.slurm("sinfo"))?);
        Ok(())
    }

    /// A Slurm client (or daemon) pointed at this cluster's configuration.
    fn slurm(&self, name: &str) -> Command {
        let mut c = Command::new(program(name).unwrap_or_else(|| PathBuf::from(name)));
        c.env("SLURM_CONF", &self.conf).current_dir(&self.work);
        c
    }

    fn spawn(&mut self, name: &'static str, mut cmd: Command) -> Result<()> {
        let log = std::fs::File::create(self.work.join("log").join(format!("{name}.log")))?;
        let child = cmd
            .env("SLURM_CONF", &self.conf)
            .current_dir(&self.work)
            .stdin(Stdio::null())
            .stdout(log.try_clone()?)
            .stderr(log)
            .spawn()
            .with_context(|| format!("starting {name}"))?;
        let mut pids = std::fs::read_to_string(self.work.join("daemons.pid")).unwrap_or_default();
        let _ = writeln!(pids, "{name} {}", child.id());
        std::fs::write(self.work.join("daemons.pid"), pids)?;
        self.daemons.push((name, child));
        Ok(())
    }

    /// Polls `ready` until it holds; fails when `timeout` passes or a daemon exits.
    fn wait_until(
        &mut self,
        what: &str,
        timeout: Duration,
        ready: impl Fn(&Cluster) -> Result<bool>,
    ) -> Result<()> {
        let start = Instant::now();
        loop {
            for (name, child) in &mut self.daemons {
                if let Some(status) = child.try_wait()? {
                    bail!(
                        "{name} exited ({status}); its log:\n{}",
                        tail(&self.work.join("log").join(format!("{name}.log")), 20)
                    );
                }
            }
            if ready(self).unwrap_or(false) {
                return Ok(());
            }
            if start.elapsed() > timeout {
                bail!(
                    "{what} not ready after {} s; its log:\n{}",
                    timeout.as_secs(),
                    tail(&self.work.join("log").join(format!("{what}.log")), 20)
                );
            }
            std::thread::sleep(Duration::from_millis(500));
        }
    }

    fn sbatch(&mut self, t: &mut Transcript, args: &[&str]) -> Result<String> {
        t.cmd(&format!("sbatch {}", args.join(" ")));
        let out = capture(self.slurm("sbatch").args(args))?;
        let id = out.trim().split(';').next().unwrap_or("").to_string();
        if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
            bail!("sbatch printed `{}`, not a job id", out.trim());
        }
        t.out(&format!("job {id}"));
        self.jobs.push(id.clone());
        Ok(id)
    }

    /// `(state, exit code)` of one job or array task (`JOB_TASK`), from `scontrol`.
    fn job_state(&self, id: &str) -> Result<(String, String)> {
        let line = capture(self.slurm("scontrol").args(["show", "job", "-o", id]))?;
        let field = |k: &str| {
            line.split_whitespace()
                .find_map(|f| f.strip_prefix(k))
                .map(str::to_string)
                .with_context(|| format!("scontrol show job {id}: no {k} in `{}`", line.trim()))
        };
        Ok((field("JobState=")?, field("ExitCode=")?))
    }

    /// The `squeue` lines of this check's jobs, finished ones included.
    fn queue(&self) -> Result<String> {
        capture(self.slurm("squeue").args([
            "-h",
            "-t",
            "all",
            "-j",
            &self.jobs.join(","),
            "-o",
            "%i %T %M %r",
        ]))
    }

    /// Waits until none of this check's jobs is pending or running; prints state changes.
    fn wait_all(&self, t: &mut Transcript, deadline: Instant) -> Result<()> {
        let mut last = String::new();
        loop {
            let q = self.queue()?;
            let states: String = q
                .lines()
                .map(|l| l.split_whitespace().take(2).collect::<Vec<_>>().join(" "))
                .collect::<Vec<_>>()
                .join(", ");
            if states != last {
                t.say(&format!("squeue: {states}"));
                last = states;
            }
            if q.lines().all(|l| {
                l.split_whitespace()
                    .nth(1)
                    .is_some_and(|s| TERMINAL.contains(&s))
            }) {
                return Ok(());
            }
            if Instant::now() > deadline {
                bail!("jobs still running at the time limit:\n{q}");
            }
            std::thread::sleep(Duration::from_secs(2));
        }
    }

    fn stop(&mut self) {
        if self.daemons.is_empty() {
            return;
        }
        if !self.jobs.is_empty()
            && let Ok(q) = self.queue()
        {
            let active: Vec<&str> = q
                .lines()
                .filter(|l| {
                    l.split_whitespace()
                        .nth(1)
                        .is_some_and(|s| !TERMINAL.contains(&s))
                })
                .filter_map(|l| l.split_whitespace().next())
                .collect();
            if !active.is_empty() {
                println!("cancelling jobs still queued: {}", active.join(" "));
                let _ = self.slurm("scancel").args(&self.jobs).status();
                std::thread::sleep(Duration::from_secs(5));
            }
        }
        while let Some((name, mut child)) = self.daemons.pop() {
            let pid = child.id();
            let _ = Command::new("kill")
                .args(["-TERM", &pid.to_string()])
                .status();
            let start = Instant::now();
            let mut stopped = false;
            while start.elapsed() < Duration::from_secs(20) {
                if let Ok(Some(_)) = child.try_wait() {
                    stopped = true;
                    break;
                }
                std::thread::sleep(Duration::from_millis(200));
            }
            if !stopped {
                let _ = child.kill();
                let _ = child.wait();
            }
            println!(
                "stopped {name} (pid {pid}{})",
                if stopped { "" } else { ", killed" }
            );
        }
        let _ = std::fs::remove_file(self.work.join("daemons.pid"));
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Job states after which a job never runs again.
const TERMINAL: [&str; 10] = [
    "COMPLETED",
    "CANCELLED",
    "FAILED",
    "TIMEOUT",
    "NODE_FAIL",
    "PREEMPTED",
    "OUT_OF_MEMORY",
    "BOOT_FAIL",
    "DEADLINE",
    "REVOKED",
];

fn need(name: &str) -> Result<PathBuf> {
    program(name).with_context(|| format!("{name} not found"))
}

fn random_key() -> Result<Vec<u8>> {
    use std::io::Read;
    let mut key = vec![0u8; 128];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut key)?;
    Ok(key)
}

/// Runs `cmd`, failing with its stderr when it fails; returns its stdout.
fn capture(cmd: &mut Command) -> Result<String> {
    let out = cmd
        .output()
        .with_context(|| format!("running {:?}", cmd.get_program()))?;
    if !out.status.success() {
        bail!(
            "{:?} {:?} failed ({}): {}{}",
            cmd.get_program(),
            cmd.get_args().collect::<Vec<_>>(),
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The last `n` lines of a log, progress bars (`\r`) reduced to their last state.
fn tail(path: &Path, n: usize) -> String {
    let text = std::fs::read(path).unwrap_or_default();
    let text = String::from_utf8_lossy(&text);
    let lines: Vec<&str> = text
        .lines()
        .map(|l| l.rsplit('\r').find(|s| !s.trim().is_empty()).unwrap_or(""))
        .filter(|l| !l.trim().is_empty())
        .collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

fn slurm_conf(work: &Path, node: &str, hardware: &str, socket: &Path) -> String {
    let w = work.display();
    format!(
        "# One-node cluster of `cargo xtask slurm-check` (Slurm 22.05, Debian 12).
ClusterName=bittcheck
SlurmctldHost={node}(127.0.0.1)
SlurmctldPort={CTLD_PORT}
SlurmdPort={SLURMD_PORT}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={socket}
StateSaveLocation={w}/state
SlurmdSpoolDir={w}/spool
SlurmctldPidFile={w}/slurmctld.pid
SlurmdPidFile={w}/slurmd.pid
SlurmctldLogFile={w}/log/slurmctld-file.log
SlurmdLogFile={w}/log/slurmd-file.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
ReturnToService=2
MailProg=/bin/true
MinJobAge=3600
NodeName={node} NodeAddr=127.0.0.1 {hardware} State=UNKNOWN
PartitionName=check Nodes={node} Default=YES MaxTime=INFINITE State=UP
",
        socket = socket.display()
    )
}

/// The job array's script: one shard of the evaluation per task.
fn job_script(bitt: &Path, out: &Path, cache: &Path, logs: &Path) -> String {
    format!(
        "#!/bin/bash
#SBATCH --job-name=bitt-eval
#SBATCH --array=0-{last}
#SBATCH --cpus-per-task=1
#SBATCH --output={logs}/eval-%A_%a.out
# Shard i of {SHARDS}: scenes k with k % {SHARDS} == i. Every task writes one file per scene
# and mesh setting into the same --out; a rerun skips the results already there.
set -euo pipefail
exec {bitt} {eval} --shard \"${{SLURM_ARRAY_TASK_ID}}/{SHARDS}\" \\
    --out {out} --cache {cache}
",
        last = SHARDS - 1,
        logs = logs.display(),
        bitt = bitt.display(),
        eval = EVAL_ARGS.join(" "),
        out = out.display(),
        cache = cache.display(),
    )
}

fn run(o: &Options, t: &mut Transcript) -> Result<()> {
    let deadline = Instant::now() + o.timeout;
    install(t)?;
    // A copy of the release binary: a rebuild during the check must not change it.
    let built = match &o.bitt {
        Some(p) => p.clone(),
        None => {
            t.say("building the release binary (cargo build --release -p bitt-cli --bin bitt)");
            crate::build_bitt()?
        }
    };
    let bitt = o.work.join("bin/bitt");
    std::fs::copy(&built, &bitt)
        .with_context(|| format!("copying {} to {}", built.display(), bitt.display()))?;
    t.say(&format!(
        "bitt: {} (copy of {})",
        bitt.display(),
        built.display()
    ));

    let mut cluster = Cluster::start(&o.work, t)?;
    let c = &mut cluster;
    t.say("a trivial job first");
    let trivial = c.sbatch(
        t,
        &[
            "--parsable",
            "--output=logs/hostname-%j.out",
            "--wrap",
            "hostname",
        ],
    )?;
    c.wait_all(t, deadline)?;
    let (state, code) = c.job_state(&trivial)?;
    if state != "COMPLETED" || code != "0:0" {
        bail!("the trivial job ended {state} (exit {code})");
    }
    t.out(&format!(
        "hostname job: {state}, printed `{}`",
        tail(&o.work.join(format!("logs/hostname-{trivial}.out")), 1)
    ));

    // The job array.
    let out = o.work.join("eval-array");
    let cache = o.work.join("cache-array");
    let logs = o.work.join("logs");
    let script = o.work.join("eval.sbatch");
    std::fs::write(&script, job_script(&bitt, &out, &cache, &logs))?;
    t.say(&format!("{}:", script.display()));
    t.out(&std::fs::read_to_string(&script)?);
    let array_started = Instant::now();
    let job = c.sbatch(t, &["--parsable", "eval.sbatch"])?;
    let victim = format!("{job}_{CANCEL_TASK}");
    let victim_log = logs.join(format!("eval-{job}_{CANCEL_TASK}.out"));
    // Cancel the victim during its second scene result, after the first was written: the
    // progress line is labelled `[k/n] SEED SETTING` and the label moves to `[2/n]` only
    // once result 1 is on disk.
    t.say(&format!(
        "waiting for task {victim} to start its second scene result (`[2/` in its log)"
    ));
    loop {
        let (state, _) = c.job_state(&victim)?;
        let log = std::fs::read_to_string(&victim_log).unwrap_or_default();
        if state == "RUNNING" && log.contains("[2/") {
            break;
        }
        if TERMINAL.contains(&state.as_str()) {
            bail!(
                "task {victim} ended ({state}) before it could be cancelled; its log:\n{}",
                tail(&victim_log, 10)
            );
        }
        if Instant::now() > deadline {
            bail!("task {victim} did not reach its second scene result in time");
        }
        std::thread::sleep(Duration::from_millis(250));
    }
    let written = scene_files(&out)?;
    t.say(&format!(
        "task {victim} is at `{}`; scene results on disk (all tasks): {}",
        tail(&victim_log, 1),
        written.len()
    ));
    t.cmd(&format!("scancel {victim}"));
    capture(c.slurm("scancel").arg(&victim))?;
    loop {
        let (state, code) = c.job_state(&victim)?;
        if TERMINAL.contains(&state.as_str()) {
            t.out(&format!("{victim}: {state} (exit {code})"));
            if state != "CANCELLED" {
                bail!("task {victim} ended {state}, not CANCELLED");
            }
            break;
        }
        if Instant::now() > deadline {
            bail!("task {victim} did not stop after scancel");
        }
        std::thread::sleep(Duration::from_millis(250));
    }
    t.out(&format!(
        "its log ends: {}",
        tail(&victim_log, 2).replace('\n', " | ")
    ));
    let rerun = c.sbatch(
        t,
        &[
            "--parsable",
            &format!("--array={CANCEL_TASK}"),
            "eval.sbatch",
        ],
    )?;
    c.wait_all(t, deadline)?;
    let array_minutes = array_started.elapsed().as_secs_f64() / 60.0;
    // Every task's end state.
    let mut bad = Vec::new();
    let mut tasks: Vec<(String, &str)> = (0..SHARDS)
        .map(|k| {
            let want = if k == CANCEL_TASK {
                "CANCELLED"
            } else {
                "COMPLETED"
            };
            (format!("{job}_{k}"), want)
        })
        .collect();
    tasks.push((format!("{rerun}_{CANCEL_TASK}"), "COMPLETED"));
    for (id, want) in &tasks {
        let (state, code) = c.job_state(id)?;
        let log = logs.join(format!("eval-{id}.out"));
        t.out(&format!(
            "{id}: {state} (exit {code}); log ends: {}",
            tail(&log, 1)
        ));
        if state != *want || (*want == "COMPLETED" && code != "0:0") {
            bad.push(format!("{id} ended {state} (exit {code}), expected {want}"));
        }
    }
    if !bad.is_empty() {
        bail!("{}", bad.join("; "));
    }
    let rerun_log = std::fs::read_to_string(logs.join(format!("eval-{rerun}_{CANCEL_TASK}.out")))?;
    match rerun_log.lines().find(|l| l.contains("already in")) {
        Some(l) => t.say(&format!("the resubmitted task resumed: `{}`", l.trim())),
        None => bail!(
            "the resubmitted task {rerun}_{CANCEL_TASK} did not skip the result its cancelled \
             run wrote (no `already in` line in its log)"
        ),
    }
    t.say(&format!("job array done in {array_minutes:.1} min"));
    let leftovers: Vec<String> = std::fs::read_dir(out.join("scenes"))?
        .chain(std::fs::read_dir(&out)?)
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains(".tmp"))
        .collect();
    if !leftovers.is_empty() {
        t.say(&format!(
            "note: temporaries left by the cancelled task: {}",
            leftovers.join(", ")
        ));
    }
    drop(cluster);
    t.say("cluster stopped");

    // Merge, then the same evaluation in one process.
    t.cmd(&format!("bitt eval-merge --out {}", out.display()));
    let merged = capture(Command::new(&bitt).arg("eval-merge").arg("--out").arg(&out))?;
    t.out(&merged.lines().take(12).collect::<Vec<_>>().join("\n"));
    let single = o.work.join("eval-single");
    let single_cache = o.work.join("cache-single");
    t.cmd(&format!(
        "bitt {} --out {} --cache {}",
        EVAL_ARGS.join(" "),
        single.display(),
        single_cache.display()
    ));
    let single_started = Instant::now();
    let log = std::fs::File::create(logs.join("eval-single.out"))?;
    let status = Command::new(&bitt)
        .args(EVAL_ARGS)
        .arg("--out")
        .arg(&single)
        .arg("--cache")
        .arg(&single_cache)
        .stdout(log.try_clone()?)
        .stderr(log)
        .status()?;
    if !status.success() {
        bail!(
            "the single-process evaluation failed ({status}):\n{}",
            tail(&logs.join("eval-single.out"), 15)
        );
    }
    t.out(&format!(
        "done in {:.1} min; log ends: {}",
        single_started.elapsed().as_secs_f64() / 60.0,
        tail(&logs.join("eval-single.out"), 1)
    ));
    compare_runs(&out, &single, t)
}

fn scene_files(out: &Path) -> Result<Vec<String>> {
    let mut names: Vec<String> = match std::fs::read_dir(out.join("scenes")) {
        Ok(d) => d
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".json") && !n.starts_with('.'))
            .collect(),
        Err(_) => Vec::new(),
    };
    names.sort();
    Ok(names)
}

/// Drops the lines holding a `seconds` field (training wall times, the one thing that may
/// differ between two runs of the same evaluation).
fn without_seconds(text: &str) -> (String, usize) {
    let mut dropped = 0;
    let kept: Vec<&str> = text
        .lines()
        .filter(|l| {
            let timing = l.trim_start().starts_with("\"seconds\":");
            dropped += usize::from(timing);
            !timing
        })
        .collect();
    (kept.join("\n"), dropped)
}

/// Paths (`a.b[2].c`) where two JSON values differ, `seconds` fields ignored.
fn json_diff(a: &serde_json::Value, b: &serde_json::Value, path: &str, out: &mut Vec<String>) {
    use serde_json::Value;
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for (k, v) in x {
                if k == "seconds" {
                    continue;
                }
                match y.get(k) {
                    Some(w) => json_diff(v, w, &format!("{path}.{k}"), out),
                    None => out.push(format!("{path}.{k}: only in the merged results")),
                }
            }
            for k in y.keys().filter(|k| !x.contains_key(*k) && *k != "seconds") {
                out.push(format!("{path}.{k}: only in the single run"));
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (v, w)) in x.iter().zip(y).enumerate() {
                json_diff(v, w, &format!("{path}[{i}]"), out);
            }
        }
        _ if a != b => out.push(format!("{path}: {a} vs {b}")),
        _ => {}
    }
}

fn count_numbers(v: &serde_json::Value) -> usize {
    match v {
        serde_json::Value::Number(_) => 1,
        serde_json::Value::Array(a) => a.iter().map(count_numbers).sum(),
        serde_json::Value::Object(o) => o
            .iter()
            .filter(|(k, _)| *k != "seconds")
            .map(|(_, v)| count_numbers(v))
            .sum(),
        _ => 0,
    }
}

/// Compares the merged job-array results with the single run's; fails on any difference
/// but the `seconds` fields.
fn compare_runs(merged: &Path, single: &Path, t: &mut Transcript) -> Result<()> {
    t.say(&format!(
        "comparing {} with {}",
        merged.display(),
        single.display()
    ));
    let (a, b) = (scene_files(merged)?, scene_files(single)?);
    if a != b || a.is_empty() {
        bail!(
            "scene results differ: merged has {} ({}), single has {} ({})",
            a.len(),
            a.join(", "),
            b.len(),
            b.join(", ")
        );
    }
    let mut problems = Vec::new();
    let mut numbers = 0;
    let mut timings = 0;
    let files: Vec<PathBuf> = a
        .iter()
        .map(|n| Path::new("scenes").join(n))
        .chain([PathBuf::from("results.json")])
        .collect();
    for f in &files {
        let x = std::fs::read_to_string(merged.join(f))?;
        let y = std::fs::read_to_string(single.join(f))?;
        let ((xs, dropped), (ys, _)) = (without_seconds(&x), without_seconds(&y));
        let xv: serde_json::Value = serde_json::from_str(&x)?;
        let yv: serde_json::Value = serde_json::from_str(&y)?;
        numbers += count_numbers(&xv);
        timings += dropped;
        if xs != ys {
            let mut diff = Vec::new();
            json_diff(&xv, &yv, "", &mut diff);
            if diff.is_empty() {
                diff.push("the texts differ (same values as parsed)".into());
            }
            let n = diff.len();
            diff.truncate(8);
            problems.push(format!(
                "{}: {n} difference(s): {}",
                f.display(),
                diff.join("; ")
            ));
        }
    }
    t.out(&format!(
        "{} files (scenes/*.json, results.json): {numbers} numbers compared as text, \
         {timings} `seconds` fields excluded",
        files.len()
    ));
    // The contact sheets, byte for byte.
    let mut sheets: Vec<String> = std::fs::read_dir(merged.join("sheets"))
        .map(|d| {
            d.filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| !n.starts_with('.'))
                .collect()
        })
        .unwrap_or_default();
    sheets.sort();
    for s in &sheets {
        let x = std::fs::read(merged.join("sheets").join(s))?;
        let y = std::fs::read(single.join("sheets").join(s)).unwrap_or_default();
        if x != y {
            problems.push(format!("sheets/{s} differs"));
        }
    }
    t.out(&format!(
        "{} contact sheet files compared byte for byte",
        sheets.len()
    ));
    if !problems.is_empty() {
        for p in &problems {
            t.out(p);
        }
        bail!("the merged job-array results differ from the single-process run");
    }
    t.say("merged results == single-process results (all but `seconds`, bit for bit)");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_seconds_are_excluded() {
        let a = "{\n  \"psnr\": 30.5,\n  \"seconds\": 1.25\n}";
        let b = "{\n  \"psnr\": 30.5,\n  \"seconds\": 9.5\n}";
        let c = "{\n  \"psnr\": 30.500000000000004,\n  \"seconds\": 1.25\n}";
        assert_eq!(without_seconds(a), without_seconds(b));
        assert_eq!(without_seconds(a).1, 1);
        assert_ne!(without_seconds(a).0, without_seconds(c).0);
        let v = |s: &str| serde_json::from_str::<serde_json::Value>(s).unwrap();
        let mut diff = Vec::new();
        json_diff(&v(a), &v(b), "", &mut diff);
        assert!(diff.is_empty(), "{diff:?}");
        json_diff(&v(a), &v(c), "", &mut diff);
        assert_eq!(diff.len(), 1, "{diff:?}");
        assert!(diff[0].starts_with(".psnr"), "{diff:?}");
        assert_eq!(count_numbers(&v(a)), 1);
    }
}
