//! The sharded bake on a real batch engine: a single-node Slurm cluster on this
//! machine (`deploy/slurm/local-cluster.sh`, Debian's slurm-wlm daemons, which
//! `.ci/setup` installs) runs `sylva-bake demo --shard I/3` as a 3-task array job
//! and `sylva-bake merge` as a job depending on it (`deploy/slurm/bake.sh`). The
//! merged scene must equal a single-process bake byte for byte.
//!
//! Skipped, with a message, where Slurm is not installed or the test is not root
//! (slurmd starts jobs as their user) — except under CI, where setup installs it.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{bin, run, snapshot, tmp};

fn deploy(script: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/slurm").join(script)
}

/// Stops the local cluster however the test ends.
struct Cluster(PathBuf);

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new("bash").arg(deploy("local-cluster.sh")).arg("stop").arg(&self.0).status();
    }
}

fn slurm_missing() -> Option<String> {
    let missing: Vec<&str> =
        ["munged", "slurmctld", "slurmd"].into_iter().filter(|d| !Path::new("/usr/sbin").join(d).exists()).collect();
    if !missing.is_empty() {
        return Some(format!(
            "{} not installed (.ci/setup installs slurmctld, slurmd, slurm-client, munge)",
            missing.join(", ")
        ));
    }
    let uid = Command::new("id").arg("-u").output().ok().map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string());
    (uid.as_deref() != Some("0")).then(|| "not root (slurmd starts jobs as their submitting user)".to_string())
}

#[test]
fn an_array_job_and_a_dependent_merge_on_slurm_equal_one_process() {
    if let Some(why) = slurm_missing() {
        assert!(std::env::var_os("CI").is_none(), "CI must run the Slurm test: {why}");
        eprintln!("skipping the Slurm array-job test: {why}");
        return;
    }
    let dir = tmp("slurm");
    let cluster = Cluster(dir.join("cluster"));
    let up = Command::new("bash").arg(deploy("local-cluster.sh")).arg("start").arg(&cluster.0).output().unwrap();
    assert!(up.status.success(), "the local cluster did not start: {}", String::from_utf8_lossy(&up.stderr));
    let conf = cluster.0.join("slurm.conf");

    let demo = [
        "demo",
        "--trees",
        "6000",
        "--seed",
        "5",
        "--billboard-size",
        "16",
        "--texture-size",
        "16",
        "--cluster-tries",
        "1",
        "--cell-size",
        "32",
        "--tile-cells",
        "2",
        "--index-node-tiles",
        "5",
    ];
    run(bin().args(demo).arg("--out").arg(dir.join("single")));

    // Submitted as a user would: the array and the dependent merge, waited for.
    let out = Command::new("bash")
        .arg(deploy("bake.sh"))
        .args(["--shards", "3", "--wait", "--out"])
        .arg(dir.join("merged"))
        .arg("--")
        .args(demo)
        .env("SYLVA_BAKE", env!("CARGO_BIN_EXE_sylva-bake"))
        .env("SLURM_CONF", &conf)
        .env_remove("XDG_RUNTIME_DIR")
        .current_dir(&dir)
        .output()
        .unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "bake.sh failed: {said}");
    let ids: Vec<u64> = said
        .split(|c: char| !c.is_ascii_digit())
        .filter(|w| !w.is_empty())
        .take(2)
        .map(|w| w.parse().unwrap())
        .collect();
    assert!(said.starts_with("array job ") && ids.len() == 2 && ids[1] > ids[0], "{said}");

    // Three tasks of one array ran the shards (each wrote its part and its log).
    for i in 0..3 {
        let part = dir.join(format!("merged.parts/part-{i}/scene.json"));
        let stamp: serde_json::Value = serde_json::from_slice(&std::fs::read(&part).unwrap()).unwrap();
        assert_eq!(stamp["shard"]["index"], i, "{}", part.display());
        assert_eq!(stamp["shard"]["count"], 3);
        assert!(dir.join(format!("merged.parts/logs/shard-{i}.log")).exists());
    }
    let single = snapshot(&dir.join("single"));
    let merged = snapshot(&dir.join("merged"));
    assert!(single.len() > 10 && single.iter().any(|(p, _)| p.ends_with(".ids")), "a whole scene, tree ids included");
    assert_eq!(
        single.iter().map(|(p, _)| p).collect::<Vec<_>>(),
        merged.iter().map(|(p, _)| p).collect::<Vec<_>>(),
        "same files"
    );
    for ((path, a), (_, b)) in single.iter().zip(&merged) {
        assert!(a == b, "{path} differs between the single bake and the one merged on Slurm");
    }

    // A shard that fails cancels the merge: no scene, and the script says so with the logs.
    let out = Command::new("bash")
        .arg(deploy("bake.sh"))
        .args(["--shards", "2", "--wait", "--out"])
        .arg(dir.join("failed"))
        .args(["--", "bake", "--placements", "missing.csv", "--model", "oak=missing.glb"])
        .env("SYLVA_BAKE", env!("CARGO_BIN_EXE_sylva-bake"))
        .env("SLURM_CONF", &conf)
        .current_dir(&dir)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && !dir.join("failed/scene.json").exists(), "{said}");
    assert!(said.contains("did not finish") && said.contains("missing"), "{said}");
}
