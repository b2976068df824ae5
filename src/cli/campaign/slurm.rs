//! `hitl campaign slurm M.toml --out DIR [--submit]`: an sbatch script that plays a manifest as a
//! Slurm job array, one task per case (`--array=0-(N-1)%LIMIT`), each task running
//! `hitl campaign run M.toml --out DIR --index $SLURM_ARRAY_TASK_ID --plain --jobs 1` with the
//! binary's and its shared libraries' absolute paths (LD_LIBRARY_PATH), so a node needs no
//! checkout. A task's loop runs on the normal scheduler where the cluster grants no real-time
//! priority (hitl run says so and goes on). `--submit` hands the script to sbatch.

use super::SlurmArgs;
use crate::exit;
use std::path::{Path, PathBuf};

/// The longest time limit written, in minutes (365 days). Slurm keeps a limit as 32-bit minutes
/// with its top values meaning INFINITE and NO_VAL; far below those, no partition grants a year.
pub const MAX_TIME_MIN: u64 = 365 * 24 * 60;

/// Everything the script says.
#[derive(Debug, Clone)]
pub struct Script {
    pub name: String,
    pub cases: usize,
    pub limit: u64,
    pub cpus_per_task: u64,
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

/// A value of an `#SBATCH` line as sbatch reads it (its own parser: whitespace ends an argument
/// and `#` starts a comment unless quoted, a backslash escapes the next character): double-quoted
/// with `"` and `\` escaped when it holds any of those. Control characters never reach here.
fn directive(s: &str) -> String {
    if s.chars().any(|c| c.is_whitespace() || "\"'\\#".contains(c)) {
        format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
    } else {
        s.to_string()
    }
}

/// The job name: `hitl-NAME` with anything but letters, digits and `_.+-` made `-`.
fn job_name(name: &str) -> String {
    let clean: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || "_.+-".contains(c) { c } else { '-' })
        .collect();
    format!("hitl-{clean}")
}

/// Whether `s` is a Slurm partition or account name as the script accepts it: 1-64 of letters,
/// digits and `_.-` (a partition may be a comma-separated list of them).
fn slurm_name(s: &str, list: bool) -> bool {
    let one = |n: &str| {
        (1..=64).contains(&n.len())
            && n.chars().all(|c| c.is_ascii_alphanumeric() || "_.-".contains(c))
    };
    if list {
        s.split(',').all(one)
    } else {
        one(s)
    }
}

/// Whether `s` is a memory size as `sbatch --mem` takes it: a whole number of at most 12 digits
/// with an optional unit K, M, G or T.
fn slurm_mem(s: &str) -> bool {
    let digits = s.strip_suffix(['K', 'M', 'G', 'T', 'k', 'm', 'g', 't']).unwrap_or(s);
    (1..=12).contains(&digits.len()) && digits.chars().all(|c| c.is_ascii_digit())
}

impl Script {
    /// Refuse what the script cannot say safely: every field is checked against Slurm's syntax
    /// or confined to characters that cannot leave its line or its quotes.
    pub fn check(&self) -> Result<(), String> {
        if let Some(why) = super::manifest::name_problem(&self.name) {
            return Err(format!("campaign name {:?} {why}", self.name));
        }
        if self.cases == 0 || self.cases > super::manifest::MAX_CASES {
            return Err(format!(
                "{} cases: an array has 1-{} tasks",
                self.cases,
                super::manifest::MAX_CASES
            ));
        }
        if self.limit == 0 {
            return Err("--limit 0: at least one task must run at a time".into());
        }
        if self.cpus_per_task == 0 {
            return Err("--cpus-per-task 0: a task needs a CPU".into());
        }
        if !(1..=MAX_TIME_MIN).contains(&self.time_min) {
            return Err(format!(
                "a time limit of {} minutes: give --time-min from 1 to {MAX_TIME_MIN} (365 days)",
                self.time_min
            ));
        }
        if !slurm_mem(&self.mem) {
            return Err(format!(
                "--mem {:?}: expected a whole number with an optional unit K, M, G or T (e.g. 4G)",
                self.mem
            ));
        }
        if let Some(part) = self.partition.as_deref().filter(|s| !slurm_name(s, true)) {
            return Err(format!(
                "--partition {part:?}: expected names of letters, digits and _.- (1-64 \
                 characters, comma-separated)"
            ));
        }
        if let Some(acct) = self.account.as_deref().filter(|s| !slurm_name(s, false)) {
            return Err(format!(
                "--account {acct:?}: expected a name of letters, digits and _.- (1-64 characters)"
            ));
        }
        let paths = [
            ("the hitl executable", Some(&self.exe)),
            ("the manifest", Some(&self.manifest)),
            ("--out", Some(&self.out)),
            ("the working folder", Some(&self.workdir)),
            ("--lib-dir", self.lib_dir.as_ref()),
        ];
        for (what, path) in paths {
            let Some(path) = path else { continue };
            let text = path.to_str().ok_or_else(|| format!("{what} {path:?} is not UTF-8"))?;
            if text.chars().any(char::is_control) {
                return Err(format!("{what} {text:?} contains a control character (newline, ...)"));
            }
        }
        // Slurm expands %-patterns in --output and a backslash turns them off: the folder name
        // must hold neither.
        for (what, path) in [("--out", &self.out), ("the working folder", &self.workdir)] {
            if path.to_string_lossy().contains(['%', '\\']) {
                return Err(format!(
                    "{what} {} contains `%` or `\\` (Slurm patterns)",
                    path.display()
                ));
            }
        }
        Ok(())
    }
}

/// The sbatch script text (of a [`Script::check`]ed script).
pub fn render(s: &Script) -> String {
    let mut t = String::from("#!/bin/bash\n");
    t += "# Written by `hitl campaign slurm`: one array task per campaign case.\n";
    t += &format!("#SBATCH --job-name={}\n", job_name(&s.name));
    t += &format!("#SBATCH --array=0-{}%{}\n", s.cases.saturating_sub(1), s.limit);
    t += "#SBATCH --ntasks=1\n";
    t += &format!("#SBATCH --cpus-per-task={}\n", s.cpus_per_task);
    t += &format!("#SBATCH --mem={}\n", s.mem);
    t += &format!("#SBATCH --time={}:{:02}:00\n", s.time_min / 60, s.time_min % 60);
    let output = format!("{}/slurm/%A_%a.out", s.out.to_string_lossy());
    t += &format!("#SBATCH --output={}\n", directive(&output));
    t += &format!("#SBATCH --chdir={}\n", directive(&s.workdir.to_string_lossy()));
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

/// The default time limit: the longest case's playback times 4 (planning, rendering and eval on
/// a busy node), in whole minutes, plus 10 minutes; `None` past [`MAX_TIME_MIN`].
pub fn default_time_min(longest_duration_s: f64) -> Option<u64> {
    if !longest_duration_s.is_finite() {
        return None;
    }
    let minutes = (longest_duration_s.max(0.0) * 4.0 / 60.0).ceil();
    if !(minutes.is_finite() && minutes <= MAX_TIME_MIN as f64) {
        return None;
    }
    (minutes as u64).checked_add(10).filter(|&m| m <= MAX_TIME_MIN)
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
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => {
            crate::errln!("hitl campaign slurm: cannot find this executable: {e}");
            return exit::BAD_INPUT;
        }
    };
    let time_min = match a.time_min {
        Some(t) => Some(t),
        None => default_time_min(m.max_number("duration_s").unwrap_or(0.0)),
    };
    let Some(time_min) = time_min else {
        crate::errln!(
            "hitl campaign slurm: the longest case's default time limit is past {MAX_TIME_MIN} \
             minutes (365 days); give --time-min"
        );
        return exit::BAD_INPUT;
    };
    let out = absolute(&a.out);
    let s = Script {
        name: m.name.clone(),
        cases: m.len(),
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
    if let Err(e) = s.check() {
        crate::errln!("hitl campaign slurm: {e}; nothing written");
        return exit::BAD_INPUT;
    }
    if let Err(e) = std::fs::create_dir_all(out.join("slurm")) {
        crate::errln!("hitl campaign slurm: {}: {e}", out.display());
        return exit::BAD_INPUT;
    }
    // The name is one plain file name (checked when the manifest loaded, and again above), so
    // the default script stays in DIR/slurm/.
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
            "#SBATCH --chdir=/data/out",
            "export LD_LIBRARY_PATH=/opt/hitl/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}",
            "exec /opt/hitl/bin/hitl campaign run '/data/my campaign.toml' --out /data/out \
             --index \"$SLURM_ARRAY_TASK_ID\" --jobs 1 --plain",
        ] {
            assert!(t.lines().any(|l| l == line), "missing {line:?} in\n{t}");
        }
        assert!(!t.contains("--account"));
        assert_eq!(q("it's"), "'it'\\''s'");
        assert_eq!(shell_words(&q("/it's")), Ok(vec!["/it's".to_string()]));
    }

    fn script() -> Script {
        Script {
            name: "c".into(),
            cases: 3,
            limit: 2,
            cpus_per_task: 2,
            mem: "4G".into(),
            time_min: 30,
            partition: None,
            account: None,
            exe: "/opt/hitl".into(),
            lib_dir: None,
            manifest: "/m.toml".into(),
            out: "/out".into(),
            workdir: "/out".into(),
        }
    }

    #[test]
    fn fields_outside_slurm_syntax_are_refused() {
        let refused = |f: &dyn Fn(&mut Script)| {
            let mut s = script();
            f(&mut s);
            s.check().expect_err("refused")
        };
        assert!(refused(&|s| s.partition = Some("debug\ntouch X".into())).contains("--partition"));
        assert!(refused(&|s| s.account = Some("a b".into())).contains("--account"));
        assert!(refused(&|s| s.mem = "4G; rm".into()).contains("--mem"));
        assert!(refused(&|s| s.limit = 0).contains("--limit 0"));
        assert!(refused(&|s| s.cpus_per_task = 0).contains("--cpus-per-task"));
        assert!(refused(&|s| s.time_min = MAX_TIME_MIN + 1).contains("time limit"));
        assert!(refused(&|s| s.name = "../../x".into()).contains("name"));
        assert!(refused(&|s| s.out = "/a\nb".into()).contains("control"));
        assert!(refused(&|s| s.out = "/a%j".into()).contains('%'));
        assert_eq!(default_time_min(1e300), None);
        assert_eq!(default_time_min(f64::NAN), None);
        assert_eq!(default_time_min(60.0), Some(14));
        assert_eq!(default_time_min(0.0), Some(10));
    }

    /// The words of a shell command line as bash splits them (single and double quotes,
    /// backslash), or `Err` at an unquoted character that would do more than end a word (an
    /// operator, an expansion other than the one `$SLURM_ARRAY_TASK_ID` in double quotes, a
    /// newline, a glob or comment).
    fn shell_words(line: &str) -> Result<Vec<String>, String> {
        let mut words = Vec::new();
        let mut w = String::new();
        let mut in_word = false;
        let mut chars = line.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                ' ' => {
                    if in_word {
                        words.push(std::mem::take(&mut w));
                        in_word = false;
                    }
                }
                '\'' => {
                    in_word = true;
                    loop {
                        match chars.next() {
                            Some('\'') => break,
                            Some(x) => w.push(x),
                            None => return Err("unterminated '".into()),
                        }
                    }
                }
                '"' => {
                    in_word = true;
                    let mut inner = String::new();
                    loop {
                        match chars.next() {
                            Some('"') => break,
                            Some(x) => inner.push(x),
                            None => return Err("unterminated \"".into()),
                        }
                    }
                    if inner != "$SLURM_ARRAY_TASK_ID" {
                        return Err(format!("double-quoted {inner:?}"));
                    }
                    w.push_str(&inner);
                }
                '\\' => {
                    in_word = true;
                    match chars.next() {
                        Some('\n') | None => return Err("backslash at the end of a line".into()),
                        Some(x) => w.push(x),
                    }
                }
                c if c.is_ascii_alphanumeric() || "/._-+=:,@%".contains(c) => {
                    in_word = true;
                    w.push(c);
                }
                c => return Err(format!("unquoted {c:?}")),
            }
        }
        if in_word {
            words.push(w);
        }
        Ok(words)
    }

    /// One argument of an `#SBATCH` line as sbatch's own parser reads it (quotes group,
    /// backslash escapes, an unquoted `#` or whitespace ends it).
    fn sbatch_argument(text: &str) -> String {
        let (mut out, mut quote, mut escape) = (String::new(), None, false);
        for c in text.chars() {
            if escape {
                escape = false;
                out.push(c);
            } else if c == '\\' {
                escape = true;
            } else if let Some(q) = quote {
                if c == q {
                    quote = None;
                } else {
                    out.push(c);
                }
            } else if c == '"' || c == '\'' {
                quote = Some(c);
            } else if c == '#' || c.is_whitespace() {
                break;
            } else {
                out.push(c);
            }
        }
        out
    }

    proptest::proptest! {
        /// Whatever the user fields hold, a script is either refused or says exactly what it
        /// was given: the fixed lines and no other, every path back out of its quotes intact.
        #[test]
        fn scripts_never_carry_unquoted_user_text(
            name in "[a-z ./\n$;'\"#%\\\\-]{0,12}",
            part in proptest::option::of("[a-z0-9 ,;\n$'-]{0,10}"),
            acct in proptest::option::of("[a-z0-9 ;\n$'-]{0,10}"),
            mem in "[0-9GMk ;\n]{0,6}",
            exe in "/[a-z \n'\"$;&|()#*\\\\-]{0,12}",
            manifest in "/[a-z \n'\"$;&|()#*\\\\-]{0,12}",
            out in "/[a-z \n'\"$;#%*\\\\-]{0,12}",
            lib in proptest::option::of("/[a-z \n'\"$;`-]{0,12}"),
            limit in 0u64..5,
            time_min in 0u64..(2 * MAX_TIME_MIN),
        ) {
            let s = Script {
                name, cases: 7, limit, cpus_per_task: 1, mem, time_min, partition: part,
                account: acct, exe: exe.clone().into(), lib_dir: lib.clone().map(Into::into),
                manifest: manifest.clone().into(), out: out.clone().into(), workdir: out.clone().into(),
            };
            if s.check().is_err() {
                return Ok(());
            }
            let t = render(&s);
            let lines: Vec<&str> = t.lines().collect();
            let expected = 13 + usize::from(s.partition.is_some()) + usize::from(s.account.is_some())
                + usize::from(lib.is_some());
            proptest::prop_assert_eq!(lines.len(), expected, "{}", t);
            for l in &lines {
                proptest::prop_assert!(
                    l.starts_with('#') || l.starts_with("set -euo pipefail")
                        || l.starts_with(": \"${SLURM_ARRAY_TASK_ID:?")
                        || l.starts_with("export LD_LIBRARY_PATH=") || l.starts_with("exec "),
                    "{}", t
                );
            }
            let exec = lines.last().copied().unwrap_or_default();
            let words = shell_words(exec).map_err(|e| proptest::test_runner::TestCaseError::fail(format!("{e} in {exec}")))?;
            let want: Vec<String> = ["exec", &exe, "campaign", "run", &manifest, "--out", &out, "--index",
                "$SLURM_ARRAY_TASK_ID", "--jobs", "1", "--plain"].iter().map(|w| w.to_string()).collect();
            proptest::prop_assert_eq!(words, want);
            if let Some(lib) = &lib {
                let line = lines.iter().find(|l| l.starts_with("export ")).copied().unwrap_or_default();
                let quoted = line.trim_start_matches("export LD_LIBRARY_PATH=")
                    .trim_end_matches("${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}");
                let words = shell_words(quoted).map_err(proptest::test_runner::TestCaseError::fail)?;
                proptest::prop_assert_eq!(words, vec![lib.clone()]);
            }
            let output = lines.iter().find_map(|l| l.strip_prefix("#SBATCH ").filter(|a| a.starts_with("--output="))).unwrap_or_default();
            proptest::prop_assert_eq!(sbatch_argument(output), format!("--output={out}/slurm/%A_%a.out"));
            let job = lines.iter().find_map(|l| l.strip_prefix("#SBATCH --job-name=")).unwrap_or_default();
            proptest::prop_assert!(job.chars().all(|c| c.is_ascii_alphanumeric() || "_.+-".contains(c)));
        }
    }
}
