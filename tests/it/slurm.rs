//! deploy/slurm/ run for real: a one-machine Slurm cluster (munged, slurmctld and three
//! slurmd nodes on loopback ports, all in the test's own folder) runs a campaign with the
//! batch scripts themselves, through a worker cancelled by `scancel` and a coordinator job
//! cancelled and submitted again; the runs equal `calib calibrate`'s bit for bit and no
//! evaluation the store held is simulated again.

use crate::common::*;
use serde_json::Value;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The daemons of the test's cluster, stopped (with every job of it) when dropped, also
/// when the test panics.
struct Slurm {
    dir: PathBuf,
    conf: PathBuf,
    daemons: Vec<(String, Child)>,
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn found(program: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {program}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

const PROGRAMS: [&str; 7] = [
    "slurmctld",
    "slurmd",
    "sbatch",
    "scancel",
    "squeue",
    "munged",
    "mungekey",
];

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

/// Why Slurm cannot run here, if it cannot: its programs (which `.ci/run` installs) or root.
fn unavailable() -> Option<String> {
    if let Some(missing) = PROGRAMS.iter().find(|p| !found(p)) {
        return Some(format!(
            "Slurm is not installed (no {missing}; apt-get install slurmctld slurmd \
             slurm-client munge, as .ci/run does)"
        ));
    }
    (!is_root()).then(|| "the one-machine Slurm cluster runs its daemons as root".into())
}

impl Slurm {
    /// [`Slurm::start_once`], again on other ports (in a fresh folder) when the nodes do not
    /// come up: a port found free may be taken before a daemon binds it.
    fn start(dir: &Path, nodes: usize) -> Slurm {
        for attempt in 1..=3 {
            let folder = dir.join(format!("attempt-{attempt}"));
            match Slurm::start_once(&folder, nodes) {
                Ok(slurm) => return slurm,
                Err(why) => eprintln!("slurm: {why}; starting again on other ports"),
            }
        }
        panic!(
            "the Slurm cluster did not come up in three attempts (see {})",
            dir.display()
        );
    }

    /// munged on its own socket and key, slurmctld, and slurmd nodes n1..n`nodes` of one
    /// CPU each, all on loopback ports, their state, spool and logs under `dir`; why not,
    /// when the nodes are not up within a minute.
    fn start_once(dir: &Path, nodes: usize) -> Result<Slurm, String> {
        let munge = dir.join("munge");
        for sub in ["munge", "state", "log"] {
            std::fs::create_dir_all(dir.join(sub)).unwrap();
        }
        set_mode(&munge, 0o700);
        let key = munge.join("munge.key");
        run(Command::new("mungekey")
            .args(["-c", "-b", "1024", "-k"])
            .arg(&key));
        set_mode(&key, 0o600);
        let socket = munge.join("socket");
        let mut slurm = Slurm {
            dir: dir.to_path_buf(),
            conf: dir.join("slurm.conf"),
            daemons: Vec::new(),
        };
        slurm.spawn(
            "munged",
            Command::new("munged")
                .args(["--foreground", "--force", "--socket"])
                .arg(&socket)
                .arg(format!("--key-file={}", key.display()))
                .arg(format!("--pid-file={}", munge.join("pid").display()))
                .arg(format!("--log-file={}", munge.join("log").display()))
                .arg(format!("--seed-file={}", munge.join("seed").display())),
        );
        await_condition("munged's socket", Duration::from_secs(10), || {
            socket.exists()
        });
        let d = dir.display();
        let mut conf = format!(
            "ClusterName=calibtest\n\
             SlurmctldHost=localhost\n\
             SlurmctldPort={ctld}\n\
             SlurmUser=root\n\
             SlurmdUser=root\n\
             AuthType=auth/munge\n\
             CredType=cred/munge\n\
             AuthInfo=socket={socket}\n\
             StateSaveLocation={d}/state\n\
             SlurmdSpoolDir={d}/spool/%n\n\
             SlurmctldPidFile={d}/slurmctld.pid\n\
             SlurmdPidFile={d}/slurmd-%n.pid\n\
             SlurmctldLogFile={d}/log/slurmctld.log\n\
             SlurmdLogFile={d}/log/slurmd-%n.log\n\
             ProctrackType=proctrack/linuxproc\n\
             TaskPlugin=task/none\n\
             SelectType=select/linear\n\
             SchedulerType=sched/backfill\n\
             MpiDefault=none\n\
             ReturnToService=2\n\
             KillWait=20\n\
             MinJobAge=600\n\
             JobAcctGatherType=jobacct_gather/none\n\
             AccountingStorageType=accounting_storage/none\n\
             SwitchType=switch/none\n",
            ctld = free_port(),
            socket = socket.display(),
        );
        for n in 1..=nodes {
            std::fs::create_dir_all(dir.join(format!("spool/n{n}"))).unwrap();
            conf.push_str(&format!(
                "NodeName=n{n} NodeHostname=localhost NodeAddr=127.0.0.1 Port={} CPUs=1 \
                 RealMemory=500 State=UNKNOWN\n",
                free_port()
            ));
        }
        conf.push_str(&format!(
            "PartitionName=calib Nodes=n[1-{nodes}] Default=YES MaxTime=INFINITE State=UP\n"
        ));
        std::fs::write(&slurm.conf, conf).unwrap();
        let conf = slurm.conf.clone();
        slurm.spawn(
            "slurmctld",
            Command::new("slurmctld")
                .args(["-D", "-i", "-f"])
                .arg(&conf),
        );
        for n in 1..=nodes {
            slurm.spawn(
                &format!("slurmd n{n}"),
                Command::new("slurmd")
                    .args(["-D", "-f"])
                    .arg(&conf)
                    .args(["-N", &format!("n{n}")]),
            );
        }
        let until = Instant::now() + Duration::from_secs(60);
        loop {
            let out = slurm.command("sinfo").args(["-h", "-o", "%D %t"]).output();
            let state = out.map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
            if state.as_deref().is_ok_and(|s| s == format!("{nodes} idle")) {
                return Ok(slurm);
            }
            if Instant::now() >= until {
                return Err(format!("the nodes are not idle after 60 s: {state:?}"));
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    fn spawn(&mut self, name: &str, command: &mut Command) {
        let log = std::fs::File::create(self.dir.join(format!("log/{name}.out"))).unwrap();
        let child = command
            .env("SLURM_CONF", &self.conf)
            .stdout(log.try_clone().unwrap())
            .stderr(log)
            .spawn()
            .unwrap_or_else(|e| panic!("start {name}: {e}"));
        self.daemons.push((name.to_string(), child));
    }

    /// A Slurm client command on this cluster.
    fn command(&self, program: &str) -> Command {
        let mut command = Command::new(program);
        command.env("SLURM_CONF", &self.conf);
        command
    }

    /// `sbatch --parsable ARGS` in `cwd` with `env`; the job's id.
    fn sbatch(&self, cwd: &Path, env: &[(&str, &Path)], args: &[&str]) -> String {
        let mut command = self.command("sbatch");
        command.current_dir(cwd).arg("--parsable").args(args);
        for (key, value) in env {
            command.env(key, value);
        }
        let out = command.output().unwrap();
        let id = String::from_utf8_lossy(&ok(out, "sbatch").stdout)
            .trim()
            .to_string();
        id.split(';').next().unwrap().to_string()
    }

    /// `scontrol show job ID` as one line of KEY=VALUE.
    fn job(&self, id: &str) -> String {
        let out = self
            .command("scontrol")
            .args(["show", "job", "-o", id])
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).to_string()
    }

    fn job_field(&self, id: &str, field: &str) -> String {
        let text = self.job(id);
        text.split_whitespace()
            .find_map(|w| w.strip_prefix(&format!("{field}=")))
            .unwrap_or_default()
            .to_string()
    }

    /// Whether the job still runs (or is pending or completing).
    fn active(&self, id: &str) -> bool {
        let out = self
            .command("squeue")
            .args(["-h", "-o", "%T", "-j", id])
            .output()
            .unwrap();
        !String::from_utf8_lossy(&out.stdout).trim().is_empty()
    }

    fn await_end(&self, id: &str, timeout: Duration) {
        await_condition(&format!("job {id} to end"), timeout, || !self.active(id));
    }

    fn scancel(&self, id: &str) {
        ok(self.command("scancel").arg(id).output().unwrap(), "scancel");
    }
}

impl Drop for Slurm {
    fn drop(&mut self) {
        // Every job of this cluster first (their processes are the slurmd's children's),
        // then the daemons.
        let _ = self.command("scancel").args(["--user", "root"]).output();
        let deadline = Instant::now() + Duration::from_secs(40);
        while Instant::now() < deadline {
            let out = self.command("squeue").args(["-h"]).output();
            if out.is_err() || out.is_ok_and(|o| o.stdout.is_empty()) {
                break;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        for (_, child) in self.daemons.iter_mut().rev() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

fn set_mode(path: &Path, mode: u32) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
}

fn ok(out: Output, what: &str) -> Output {
    assert!(
        out.status.success(),
        "{what}: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn run(command: &mut Command) -> Output {
    let out = command.output().unwrap();
    ok(out, &format!("{command:?}"))
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_default()
}

/// The token and a CA, and a certificate it signed for this host's name, in `home`/.calib,
/// where the scripts look for them.
fn secrets(home: &Path, host: &str) -> PathBuf {
    use rcgen::{BasicConstraints, CertificateParams, IsCa, Issuer, KeyPair, KeyUsagePurpose};
    let dir = home.join(".calib");
    std::fs::create_dir_all(&dir).unwrap();
    set_mode(&dir, 0o700);
    let ca_key = KeyPair::generate().unwrap();
    let mut ca = CertificateParams::new(Vec::<String>::new()).unwrap();
    ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    let ca_cert = ca.self_signed(&ca_key).unwrap();
    let issuer = Issuer::new(ca, ca_key);
    let key = KeyPair::generate().unwrap();
    let names = vec![host.to_string(), "localhost".into(), "127.0.0.1".into()];
    let cert = CertificateParams::new(names)
        .unwrap()
        .signed_by(&key, &issuer)
        .unwrap();
    for (name, text) in [
        ("ca.crt", ca_cert.pem()),
        ("tls.crt", cert.pem()),
        ("tls.key", key.serialize_pem()),
        ("token", "slurm-test-token-0123456789abcdef".to_string()),
    ] {
        std::fs::write(dir.join(name), text).unwrap();
        set_mode(&dir.join(name), 0o600);
    }
    dir
}

/// `calib status` of the campaign `name` on the coordinator of `calib_dir`: its
/// evaluations so far (`None` while no coordinator answers).
fn evaluations(calib_dir: &Path, secrets: &Path, name: &str) -> Option<u64> {
    let url = read(&calib_dir.join("coordinator.url"));
    if url.trim().is_empty() {
        return None;
    }
    let out = Command::new(env!("CARGO_BIN_EXE_calib"))
        .args(["status", "--coordinator", url.trim(), "--tls-ca"])
        .arg(secrets.join("ca.crt"))
        .arg("--token-file")
        .arg(secrets.join("token"))
        .output()
        .ok()?;
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|line| {
            let words: Vec<&str> = line.split_whitespace().collect();
            (words.get(2) == Some(&name)).then(|| words.get(3)?.parse().ok())?
        })
}

fn runs(result: &Value) -> Vec<Value> {
    result["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            serde_json::json!([
                r["method"],
                r["start"],
                r["objective"],
                r["parameters"],
                r["evaluations"]
            ])
        })
        .collect()
}

fn stored(db: &Path) -> u64 {
    json_of(&calib(&[
        "store",
        "stats",
        "--db",
        db.to_str().unwrap(),
        "--json",
    ]))["evaluations"]
        .as_u64()
        .unwrap()
}

#[test]
fn a_campaign_on_slurm_survives_a_cancelled_worker_and_a_resubmitted_coordinator_job() {
    if let Some(why) = unavailable() {
        skip(&why);
        return;
    }
    let started = Instant::now();
    let tmp = tempfile::tempdir().unwrap();
    let slurm = Slurm::start(&tmp.path().join("slurm"), 3);
    eprintln!(
        "slurm: 3 nodes up in {:.1} s",
        started.elapsed().as_secs_f64()
    );

    // The campaign: differential evolution from eight starts, about 16,000 evaluations: long
    // enough that the cancels at a fifth and at half of it land before its end on a fast
    // machine too (two starts, 4,041 evaluations, once finished between two polls).
    let search =
        "methods = [\"differential-evolution\"]\nstarts = 8\nmax_evaluations = 4000\nseed = 5";
    // Folders whose paths hold spaces: the scripts', and the one sbatch runs in (where the
    // deployment's files go).
    let submit_dir = tmp.path().join("submit dir");
    std::fs::create_dir_all(&submit_dir).unwrap();
    let campaign = write(&submit_dir, "campaign.toml", &clean_campaign(search));

    // The reference: the same campaign in one process.
    let t = Instant::now();
    let local = calibrate_json(
        &campaign,
        &tmp.path().join("local-db"),
        &tmp.path().join("local"),
        &[],
    );
    let total = local["evaluations"].as_u64().unwrap();
    let local_stored = stored(&tmp.path().join("local-db"));
    eprintln!(
        "local run: {total} evaluations, {local_stored} stored, in {:.1} s",
        t.elapsed().as_secs_f64()
    );

    let home = tmp.path().join("home");
    let host = read(Path::new("/proc/sys/kernel/hostname"))
        .trim()
        .to_string();
    let secrets = secrets(&home, &host);
    let calib_dir = submit_dir.join("calib");
    let deploy = tmp.path().join("deploy scripts");
    std::fs::create_dir_all(&deploy).unwrap();
    for script in ["calib.sbatch", "workers.sbatch", "worker.sh", "env.sh"] {
        let to = deploy.join(script);
        std::fs::copy(repo().join("deploy/slurm").join(script), &to).unwrap();
    }
    let binary = PathBuf::from(env!("CARGO_BIN_EXE_calib"));
    let env: [(&str, &Path); 2] = [("CALIB", &binary), ("HOME", &home)];
    let script = |name: &str| deploy.join(name).to_str().unwrap().to_string();

    // The coordinator on n1 and a worker on n2 (calib.sbatch on two nodes), and a worker
    // of the array on n3.
    let t = Instant::now();
    let job = slurm.sbatch(
        &submit_dir,
        &env,
        &[
            "--nodes=2",
            &script("calib.sbatch"),
            campaign.to_str().unwrap(),
        ],
    );
    let array = slurm.sbatch(&submit_dir, &env, &["--array=0", &script("workers.sbatch")]);
    let logs = calib_dir.join("logs");
    let coordinator_log = logs.join(format!("coordinator-{job}.log"));
    await_condition("two workers up", Duration::from_secs(60), || {
        read(&coordinator_log).matches("worker up").count() >= 2
    });
    eprintln!(
        "job {job} (coordinator, one worker) and array {array}_0 (one worker): 2 workers up \
         {:.1} s after sbatch",
        t.elapsed().as_secs_f64()
    );

    let progress = |fraction: f64, job: &str| {
        let goal = (total as f64 * fraction) as u64;
        let mut at = 0;
        await_condition(
            &format!("{goal} evaluations"),
            Duration::from_secs(120),
            || {
                assert!(
                    slurm.active(job),
                    "job {job} ended early: {}",
                    read(&submit_dir.join(format!("calib-{job}.out")))
                );
                // `calib status` is a process and a TLS connection: a few per second.
                std::thread::sleep(Duration::from_millis(250));
                at = evaluations(&calib_dir, &secrets, "clean").unwrap_or(0);
                at >= goal
            },
        );
        at
    };

    // scancel of the array's worker: SIGTERM, then SIGKILL after KillWait.
    let at = progress(0.2, &job);
    let task = format!("{array}_0");
    slurm.scancel(&task);
    slurm.await_end(&task, Duration::from_secs(60));
    let worker_log = read(&logs.join(format!("worker-{task}.log")));
    eprintln!(
        "scancel {task} at {at} evaluations: {} ({})",
        slurm.job_field(&task, "JobState"),
        worker_log
            .lines()
            .filter(|l| l.contains("calib worker: drain"))
            .collect::<Vec<_>>()
            .join("; ")
    );
    assert_eq!(slurm.job_field(&task, "JobState"), "CANCELLED");
    assert!(
        worker_log.contains("calib worker: drained:"),
        "the cancelled worker did not drain:\n{worker_log}"
    );

    // The coordinator job cancelled half-way (SIGTERM, then SIGKILL), then submitted again.
    let at = progress(0.5, &job);
    slurm.scancel(&job);
    slurm.await_end(&job, Duration::from_secs(60));
    let result_file = calib_dir.join("results/clean/result.json");
    assert!(
        !result_file.exists(),
        "the campaign finished before its coordinator job was cancelled"
    );
    let before = stored(&calib_dir.join("store"));
    eprintln!(
        "scancel {job} (the coordinator's job) at {at} evaluations: {}; its store holds {before}",
        slurm.job_field(&job, "JobState")
    );
    assert_eq!(slurm.job_field(&job, "JobState"), "CANCELLED");

    let again = slurm.sbatch(
        &submit_dir,
        &env,
        &[
            "--nodes=2",
            &script("calib.sbatch"),
            campaign.to_str().unwrap(),
        ],
    );
    slurm.await_end(&again, Duration::from_secs(150));
    let output = read(&submit_dir.join(format!("calib-{again}.out")));
    assert_eq!(
        (
            slurm.job_field(&again, "JobState"),
            slurm.job_field(&again, "ExitCode")
        ),
        ("COMPLETED".to_string(), "0:0".to_string()),
        "job {again}:\n{output}\n{}",
        read(&logs.join(format!("coordinator-{again}.log")))
    );
    let resumed_log = read(&logs.join(format!("coordinator-{again}.log")));
    assert!(
        resumed_log.contains("resuming submitted campaign"),
        "{resumed_log}"
    );
    let result: Value = serde_json::from_str(&read(&result_file)).unwrap();
    let after = stored(&calib_dir.join("store"));
    let simulated = result["simulated"].as_u64().unwrap();
    let evaluated = result["evaluations"].as_u64().unwrap();
    eprintln!(
        "job {again} resumed the campaign: {evaluated} evaluations (local {total}), {} from \
         the store, {simulated} simulated, {} new in the store ({after} in all, local \
         {local_stored}); whole scenario {:.1} s",
        result["cached"],
        after - before,
        started.elapsed().as_secs_f64()
    );

    // The local run's runs, bit for bit; no evaluation lost or added; nothing the store held
    // simulated again, and no point simulated that the local run did not.
    assert_eq!(runs(&result), runs(&local));
    assert_eq!(result["best"], local["best"]);
    assert_eq!(evaluated, total);
    assert_eq!(
        simulated,
        after - before,
        "simulations repeated after the resubmission"
    );
    assert_eq!(after, local_stored);
}
