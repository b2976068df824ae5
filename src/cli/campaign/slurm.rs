//! `hitl campaign slurm M.toml --out DIR [--submit]`: an sbatch script that plays a manifest as a
//! Slurm job array, one task per case (`--array=0-(N-1)%LIMIT`), each task running
//! `hitl campaign run M.toml --out DIR --index $SLURM_ARRAY_TASK_ID --plain --jobs 1` with the
//! binary's and its shared libraries' absolute paths (LD_LIBRARY_PATH), so a node needs no
//! checkout. A task's loop runs on the normal scheduler where the cluster grants no real-time
//! priority (hitl run says so and goes on). `--submit` hands the script to sbatch.

use super::SlurmArgs;
use crate::exit;
use std::path::{Path, PathBuf};

/// Everything the script says.
#[derive(Debug, Clone)]
pub struct Script {
    pub name: String,
    pub cases: usize,
    pub limit: usize,
    pub cpus_per_task: usize,
    pub mem: String,
    pub time_min: u64,
    pub partition: Option<String>,
    pub account: Option<String>,
    pub exe: PathBuf,
    pub lib_dir: Option<PathBuf>,
    pub manifest: PathBuf,
    pub out: PathBuf,
    pub workdir: PathBuf,
}

/// Shell-quote a word (single quotes).
fn q(s: &str) -> String {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "/._-+=:,@%".contains(c)) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

fn p(path: &Path) -> String {
    q(&path.to_string_lossy())
}

/// The sbatch script text.
pub fn render(s: &Script) -> String {
    let mut t = String::from("#!/bin/bash\n");
    t += "# Written by `hitl campaign slurm`: one array task per campaign case.\n";
    t += &format!("#SBATCH --job-name=hitl-{}\n", s.name.replace(|c: char| c.is_whitespace(), "-"));
    t += &format!("#SBATCH --array=0-{}%{}\n", s.cases.saturating_sub(1), s.limit.max(1));
    t += "#SBATCH --ntasks=1\n";
    t += &format!("#SBATCH --cpus-per-task={}\n", s.cpus_per_task.max(1));
    t += &format!("#SBATCH --mem={}\n", s.mem);
    t += &format!("#SBATCH --time={}:{:02}:00\n", s.time_min / 60, s.time_min % 60);
    t += &format!("#SBATCH --output={}/slurm/%A_%a.out\n", s.out.to_string_lossy());
    t += &format!("#SBATCH --chdir={}\n", s.workdir.to_string_lossy());
    if let Some(part) = &s.partition {
        t += &format!("#SBATCH --partition={part}\n");
    }
    if let Some(acct) = &s.account {
        t += &format!("#SBATCH --account={acct}\n");
    }
    t += "set -euo pipefail\n";
    t += ": \"${SLURM_ARRAY_TASK_ID:?run this script with sbatch, or set SLURM_ARRAY_TASK_ID}\"\n";
    if let Some(lib) = &s.lib_dir {
        t += &format!("export LD_LIBRARY_PATH={}${{LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}}\n", p(lib));
    }
    t += &format!(
        "exec {} campaign run {} --out {} --index \"$SLURM_ARRAY_TASK_ID\" --jobs 1 --plain\n",
        p(&s.exe),
        p(&s.manifest),
        p(&s.out)
    );
    t
}

/// The .deps/lib folder of the checkout a binary at `exe` (target/PROFILE/hitl) was built in.
pub fn default_lib_dir(exe: &Path) -> Option<PathBuf> {
    exe.ancestors().skip(1).map(|a| a.join(".deps").join("lib")).find(|d| d.is_dir())
}

fn absolute(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| {
        std::env::current_dir().map(|d| d.join(path)).unwrap_or_else(|_| path.to_path_buf())
    })
}

/// Run `hitl campaign slurm`.
pub fn run(a: &SlurmArgs) -> u8 {
    let (m, _) = match super::load(&a.manifest) {
        Ok(x) => x,
        Err(code) => return code,
    };
    if m.cases.is_empty() {
        crate::errln!("hitl campaign slurm: {} has no cases", a.manifest.display());
        return exit::BAD_INPUT;
    }
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => {
            crate::errln!("hitl campaign slurm: cannot find this executable: {e}");
            return exit::BAD_INPUT;
        }
    };
    if let Err(e) = std::fs::create_dir_all(a.out.join("slurm")) {
        crate::errln!("hitl campaign slurm: {}: {e}", a.out.display());
        return exit::BAD_INPUT;
    }
    // Default time: the longest case's playback, times 4 for planning, rendering and eval on a
    // busy node, plus 10 minutes.
    let longest = m.cases.iter().filter_map(|c| c.number("duration_s")).fold(0.0f64, f64::max);
    let time_min = a.time_min.unwrap_or(((longest * 4.0) / 60.0).ceil() as u64 + 10);
    let out = absolute(&a.out);
    let s = Script {
        name: m.name.clone(),
        cases: m.cases.len(),
        limit: a.limit,
        cpus_per_task: a.cpus_per_task,
        mem: a.mem.clone(),
        time_min,
        partition: a.partition.clone(),
        account: a.account.clone(),
        lib_dir: a.lib_dir.as_deref().map(absolute).or_else(|| default_lib_dir(&exe)),
        exe,
        manifest: absolute(&a.manifest),
        workdir: out.clone(),
        out: out.clone(),
    };
    let script =
        a.script.clone().unwrap_or_else(|| out.join("slurm").join(format!("{}.sbatch", m.name)));
    if let Err(e) = super::store::write_atomic(&script, render(&s).as_bytes()) {
        crate::errln!("hitl campaign slurm: {}: {e}", script.display());
        return exit::BAD_INPUT;
    }
    crate::outln!(
        "wrote {} ({} array tasks, at most {} at once)",
        script.display(),
        s.cases,
        s.limit
    );
    if !a.submit {
        crate::outln!("submit with: sbatch {}", script.display());
        return exit::OK;
    }
    match std::process::Command::new("sbatch").arg(&script).output() {
        Ok(o) if o.status.success() => {
            crate::out!("{}", String::from_utf8_lossy(&o.stdout));
            exit::OK
        }
        Ok(o) => {
            crate::errln!(
                "hitl campaign slurm: sbatch refused the job ({}): {}",
                o.status,
                String::from_utf8_lossy(&o.stderr).trim()
            );
            exit::DEVICE
        }
        Err(e) => {
            crate::errln!("hitl campaign slurm: cannot run sbatch: {e}");
            exit::DEVICE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_script_names_the_array_resources_and_paths() {
        let s = Script {
            name: "rq3 range".into(),
            cases: 24,
            limit: 8,
            cpus_per_task: 2,
            mem: "4G".into(),
            time_min: 75,
            partition: Some("cpu".into()),
            account: None,
            exe: "/opt/hitl/bin/hitl".into(),
            lib_dir: Some("/opt/hitl/lib".into()),
            manifest: "/data/my campaign.toml".into(),
            out: "/data/out".into(),
            workdir: "/data/out".into(),
        };
        let t = render(&s);
        assert!(t.starts_with("#!/bin/bash\n"));
        for line in [
            "#SBATCH --job-name=hitl-rq3-range",
            "#SBATCH --array=0-23%8",
            "#SBATCH --cpus-per-task=2",
            "#SBATCH --mem=4G",
            "#SBATCH --time=1:15:00",
            "#SBATCH --partition=cpu",
            "#SBATCH --output=/data/out/slurm/%A_%a.out",
            "export LD_LIBRARY_PATH=/opt/hitl/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}",
            "exec /opt/hitl/bin/hitl campaign run '/data/my campaign.toml' --out /data/out \
             --index \"$SLURM_ARRAY_TASK_ID\" --jobs 1 --plain",
        ] {
            assert!(t.lines().any(|l| l == line), "missing {line:?} in\n{t}");
        }
        assert!(!t.contains("--account"));
        assert_eq!(q("it's"), "'it'\\''s'");
    }
}
