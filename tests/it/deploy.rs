//! `deploy/`: the compose file and the Kubernetes manifests parse, say what the deployment
//! promises (a store on a volume, workers behind a headless Service, probes, limits,
//! autoscaling, Secrets), and use only `calib` subcommands and flags that exist; so do the
//! Slurm batch scripts (deploy/slurm/, run for real by tests/it/slurm.rs).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;
use yaml_rust2::{Yaml, YamlLoader};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn load(path: &Path) -> Vec<Yaml> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    YamlLoader::load_from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn yaml_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("yml" | "yaml")))
        .collect();
    files.sort();
    files
}

fn strings(node: &Yaml) -> Vec<String> {
    node.as_vec()
        .map(|v| {
            v.iter()
                .filter_map(|s| s.as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default()
}

/// Every `calib` command line in a YAML tree: the `command`/`args` of a container or service
/// whose image is calib's, and any exec list that runs the calib binary.
fn invocations(node: &Yaml, found: &mut Vec<Vec<String>>) {
    match node {
        Yaml::Hash(map) => {
            let image = map.get(&Yaml::from_str("image")).and_then(Yaml::as_str);
            if image.is_some_and(|i| i.contains("calib")) {
                for key in ["command", "args"] {
                    if let Some(list) = map.get(&Yaml::from_str(key)) {
                        found.push(strings(list));
                    }
                }
            }
            for (_, value) in map {
                invocations(value, found);
            }
        }
        Yaml::Array(items) => {
            let words = strings(node);
            if let Some(at) = words.iter().position(|w| w.ends_with("/calib")) {
                found.push(words[at + 1..].to_vec());
            }
            for item in items {
                invocations(item, found);
            }
        }
        _ => {}
    }
}

fn help(subcommand: &str) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_calib"))
        .args([subcommand, "--help"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "`calib {subcommand} --help` fails: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn every_calib_subcommand_and_flag_the_deployments_use_exists() {
    let mut files = yaml_files(&repo().join("deploy/compose"));
    files.extend(yaml_files(&repo().join("deploy/k8s")));
    assert!(files.len() >= 5, "{files:?}");
    let mut checked = BTreeSet::new();
    for file in &files {
        let mut found = Vec::new();
        for document in load(file) {
            invocations(&document, &mut found);
        }
        for words in found {
            let subcommand = words
                .first()
                .unwrap_or_else(|| panic!("{}: empty", file.display()));
            let text = help(subcommand);
            for word in words.iter().filter(|w| w.starts_with("--")) {
                let flag = word.split('=').next().unwrap();
                let shown = text
                    .split(|c: char| c.is_whitespace() || c == ',')
                    .any(|w| w == flag);
                assert!(
                    shown,
                    "{}: `calib {subcommand} {flag}` is not in `calib {subcommand} --help`",
                    file.display()
                );
                checked.insert(format!("{subcommand} {flag}"));
            }
        }
    }
    for needed in [
        "coordinator --db",
        "coordinator --workers",
        "worker --register",
        "worker --token-file",
        "health --service",
    ] {
        assert!(
            checked.contains(needed),
            "no deployment uses `{needed}`: {checked:?}"
        );
    }
}

/// The flags a shell array of deploy/slurm/env.sh holds (`serve+=(--tls-cert …)`).
fn array_flags(env: &str, array: &str) -> Vec<String> {
    env.lines()
        .filter_map(|l| l.split_once(&format!("{array}+=(")))
        .flat_map(|(_, rest)| rest.split_whitespace())
        .filter(|w| w.starts_with("--"))
        .map(|w| w.trim_end_matches(')').to_string())
        .collect()
}

/// Every `"$calib" SUBCOMMAND …` command line of the Slurm scripts (continuation lines
/// joined), as its words, with the arrays of security flags spelled out.
fn shell_invocations(dir: &Path) -> Vec<(PathBuf, Vec<String>)> {
    let env = std::fs::read_to_string(dir.join("env.sh")).unwrap();
    let mut found = Vec::new();
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            matches!(
                p.extension().and_then(|e| e.to_str()),
                Some("sh" | "sbatch")
            )
        })
        .collect();
    files.sort();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap().replace("\\\n", " ");
        for line in text.lines().filter(|l| !l.trim_start().starts_with('#')) {
            let words: Vec<&str> = line.split_whitespace().collect();
            // The command word of the line (`command -v "$calib"` runs nothing).
            let at = usize::from(words.first() == Some(&"exec"));
            if words.get(at) != Some(&"\"$calib\"") {
                continue;
            }
            let mut command = Vec::new();
            for word in &words[at + 1..] {
                if matches!(*word, "&" | "|" | ";" | "&&" | "||" | ">" | ">>") {
                    break;
                }
                match *word {
                    "\"${serve[@]}\"" => command.extend(array_flags(&env, "serve")),
                    "\"${dial[@]}\"" => command.extend(array_flags(&env, "dial")),
                    w => command.push(w.to_string()),
                }
            }
            found.push((file.clone(), command));
        }
    }
    found
}

/// Whether `calib SUBCOMMAND --help` (`text`) shows `flag`.
fn shown(text: &str, flag: &str) -> bool {
    text.split(|c: char| c.is_whitespace() || c == ',')
        .any(|w| w == flag)
}

#[test]
fn every_calib_subcommand_and_flag_the_slurm_scripts_use_exists() {
    let found = shell_invocations(&repo().join("deploy/slurm"));
    let mut checked = BTreeSet::new();
    for (file, words) in &found {
        let subcommand = words
            .first()
            .unwrap_or_else(|| panic!("{}: empty", file.display()));
        let text = help(subcommand);
        for word in words.iter().filter(|w| w.starts_with("--")) {
            let flag = word.split('=').next().unwrap();
            assert!(
                shown(&text, flag),
                "{}: `calib {subcommand} {flag}` is not in `calib {subcommand} --help`",
                file.display()
            );
            checked.insert(format!("{subcommand} {flag}"));
        }
    }
    for needed in [
        "coordinator --db",
        "coordinator --out",
        "coordinator --tls-cert",
        "coordinator --token-file",
        "worker --register",
        "worker --slots",
        "worker --tls-cert",
        "worker --token-file",
        "submit --coordinator",
        "submit --tls-ca",
        "submit --token-file",
    ] {
        assert!(
            checked.contains(needed),
            "no Slurm script uses `{needed}`: {checked:?}"
        );
    }
}

fn kind<'a>(documents: &'a [Yaml], kind: &str, name: &str) -> &'a Yaml {
    documents
        .iter()
        .find(|d| d["kind"].as_str() == Some(kind) && d["metadata"]["name"].as_str() == Some(name))
        .unwrap_or_else(|| panic!("no {kind} {name}"))
}

fn container(workload: &Yaml) -> &Yaml {
    &workload["spec"]["template"]["spec"]["containers"][0]
}

fn flag<'a>(container: &'a Yaml, name: &str) -> Option<&'a str> {
    container["args"]
        .as_vec()?
        .iter()
        .filter_map(Yaml::as_str)
        .find_map(|a| a.strip_prefix(name)?.strip_prefix('='))
}

#[test]
fn the_kubernetes_manifests_keep_the_store_find_the_workers_and_probe_them() {
    let dir = repo().join("deploy/k8s");
    let kustomization = &load(&dir.join("kustomization.yaml"))[0];
    let mut documents = Vec::new();
    for resource in strings(&kustomization["resources"]) {
        documents.extend(load(&dir.join(resource)));
    }

    // The coordinator: a StatefulSet whose store lives on a claim.
    let coordinator = kind(&documents, "StatefulSet", "calib-coordinator");
    let claim = &coordinator["spec"]["volumeClaimTemplates"][0];
    let claim_name = claim["metadata"]["name"].as_str().unwrap();
    let c = container(coordinator);
    let mounted = c["volumeMounts"]
        .as_vec()
        .unwrap()
        .iter()
        .find(|m| m["name"].as_str() == Some(claim_name))
        .expect("the claim is mounted");
    let db = flag(c, "--db").expect("--db");
    assert!(
        db.starts_with(mounted["mountPath"].as_str().unwrap()),
        "{db}"
    );

    // The workers: behind a headless Service the coordinator resolves with dns:///.
    let service = kind(&documents, "Service", "calib-workers");
    assert_eq!(service["spec"]["clusterIP"].as_str(), Some("None"));
    let workers = flag(c, "--workers").expect("--workers");
    let host = workers.strip_prefix("dns:///").expect("dns:///");
    assert!(host.starts_with("calib-workers."), "{host}");
    let port = service["spec"]["ports"][0]["port"].as_i64().unwrap();
    assert!(host.ends_with(&format!(":{port}")), "{host} vs port {port}");
    let worker = kind(&documents, "Deployment", "calib-worker");
    let w = container(worker);
    let selector = &service["spec"]["selector"];
    let labels = &worker["spec"]["template"]["metadata"]["labels"];
    for (key, value) in selector.as_hash().unwrap() {
        assert_eq!(&labels[key.as_str().unwrap()], value, "selector {key:?}");
    }

    // Probes on the gRPC health service, requests and limits, Secrets for token and TLS.
    for (name, c) in [("coordinator", c), ("worker", w)] {
        for probe in ["readinessProbe", "livenessProbe"] {
            let command = strings(&c[probe]["exec"]["command"]);
            assert_eq!(
                command.get(1).map(String::as_str),
                Some("health"),
                "{name} {probe}"
            );
        }
        for bound in ["requests", "limits"] {
            for resource in ["cpu", "memory"] {
                assert!(
                    !c["resources"][bound][resource].is_badvalue(),
                    "{name} {bound}.{resource}"
                );
            }
        }
        assert!(flag(c, "--token-file").is_some(), "{name} --token-file");
        assert!(flag(c, "--tls-cert").is_some(), "{name} --tls-cert");
    }
    let secrets: BTreeSet<&str> = [coordinator, worker]
        .iter()
        .flat_map(|w| w["spec"]["template"]["spec"]["volumes"].as_vec().unwrap())
        .filter_map(|v| v["secret"]["secretName"].as_str())
        .collect();
    assert_eq!(secrets, BTreeSet::from(["calib-tls", "calib-token"]));

    // Workers scale with their load.
    let hpa = kind(&documents, "HorizontalPodAutoscaler", "calib-worker");
    assert_eq!(
        hpa["spec"]["scaleTargetRef"]["kind"].as_str(),
        Some("Deployment")
    );
    assert_eq!(
        hpa["spec"]["scaleTargetRef"]["name"].as_str(),
        Some("calib-worker")
    );
}

#[test]
fn the_compose_workers_register_with_the_coordinator_whose_store_is_a_volume() {
    let compose = &load(&repo().join("deploy/compose/docker-compose.yml"))[0];
    let services = &compose["services"];
    let coordinator = &services["coordinator"];
    let command = strings(&coordinator["command"]);
    let db = command
        .iter()
        .find_map(|a| a.strip_prefix("--db="))
        .expect("--db");
    let volumes = strings(&coordinator["volumes"]);
    let (volume, path) = volumes[0].split_once(':').unwrap();
    assert!(db.starts_with(path), "{db} is not on the volume at {path}");
    assert!(
        !compose["volumes"][volume].is_badvalue(),
        "named volume {volume}"
    );
    let worker = strings(&services["worker"]["command"]);
    let register = worker
        .iter()
        .find_map(|a| a.strip_prefix("--register="))
        .expect("--register");
    assert_eq!(register, "http://coordinator:50050");
}

fn answers(program: &str, args: &[&str]) -> bool {
    Command::new(program)
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// deploy/fault-test.sh: a coordinator and three workers on their own hosts (containers of
/// the compose file, or network namespaces without Docker); a worker killed, another cut off
/// for 8 s, the coordinator killed and restarted, all while `calib submit` follows the
/// campaign. The script checks the runs against a local run, that no evaluation is lost and
/// that nothing the store held is simulated again, and prints the figures.
#[test]
fn the_cluster_survives_a_killed_worker_a_cut_network_and_a_restarted_coordinator() {
    let on = if answers("docker", &["info"]) && answers("docker-compose", &["version"]) {
        "docker"
    } else if answers("ip", &["netns", "list"]) && is_root() {
        "netns"
    } else {
        calib_model::testing::skip(
            "the fault test needs a Docker engine or network namespaces (root and iproute2)",
        );
        return;
    };
    // The figures go straight to the test's output.
    let status = Command::new(repo().join("deploy/fault-test.sh"))
        .args(["--binary", env!("CARGO_BIN_EXE_calib"), "--on", on])
        .status()
        .unwrap();
    assert!(status.success(), "deploy/fault-test.sh --on {on}: {status}");
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}
