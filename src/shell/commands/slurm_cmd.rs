//! `study slurm`: a Slurm job array (one task per shard, SLURM_ARRAY_TASK_ID → `--shard I/N`) and
//! a merge job that runs after every task succeeded (`--dependency=afterok`), ready to submit.

use crate::orchestration::study::batch::Plan;
use crate::orchestration::study::problem::StudySpec;
use crate::shell::cli::SlurmArgs;
use crate::shell::job::study_job::{load_study, plan_for, Shard};
use crate::shell::BadInput;
use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Single-quotes `s` for a shell script.
fn q(s: &Path) -> String {
    format!("'{}'", s.display().to_string().replace('\'', "'\\''"))
}

fn absolute(p: &Path) -> anyhow::Result<PathBuf> {
    std::fs::canonicalize(p).map_err(|e| BadInput(format!("{}: {e}", p.display())).into())
}

/// Checks a value that goes into an `#SBATCH` line (no spaces or shell characters).
fn slurm_value(flag: &str, v: &str) -> anyhow::Result<()> {
    if v.is_empty()
        || !v
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_:.,+".contains(c))
    {
        return Err(BadInput(format!(
            "--{flag} {v:?}: not a Slurm value (letters, digits and - _ : . , +)"
        ))
        .into());
    }
    Ok(())
}

/// Refuses (exit 2, before any script is written) a job script that exists with other contents: an
/// earlier `study slurm` with other options, or one edited by hand, is not replaced silently.
fn check_unchanged(path: &Path, text: &str) -> anyhow::Result<()> {
    crate::shell::job::outputs::check_output(path)?;
    match std::fs::read(path) {
        Ok(old) if old != text.as_bytes() => Err(BadInput(format!(
            "{}: exists with other contents (written by a `study slurm` with other options, or \
             edited); nothing was written: remove the folder's scripts (and its shards/), or \
             choose another --dir",
            path.display()
        ))
        .into()),
        _ => Ok(()),
    }
}

/// What the job scripts need: the study's name and size, the absolute paths, the shared
/// `#SBATCH` lines.
struct Job<'a> {
    args: &'a SlurmArgs,
    name: String,
    samples: usize,
    excitations: usize,
    dir: PathBuf,
    study: PathBuf,
    bin: PathBuf,
    /// `#SBATCH` lines every script carries (partition, account).
    common: String,
}

pub fn run(args: &SlurmArgs) -> anyhow::Result<()> {
    let job = prepare(args)?;
    let (array, merge, submit) = (array_script(&job), merge_script(&job), submit_script(&job));
    let dir = &job.dir;
    let scripts = [
        ("array.sbatch", &array),
        ("merge.sbatch", &merge),
        ("submit.sh", &submit),
    ];
    for (file, text) in scripts {
        check_unchanged(&dir.join(file), text)?;
    }
    for (file, text) in scripts {
        let path = dir.join(file);
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))?;
        }
    }
    let n = args.shards;
    let mut o = std::io::stdout().lock();
    writeln!(
        o,
        "study slurm {}: {} samples x {} excitations in {n} shards",
        args.file.display(),
        job.samples,
        job.excitations
    )?;
    writeln!(
        o,
        "  {}  the job array (task I = shard I/{n}, {} CPUs{}, {} each)",
        dir.join("array.sbatch").display(),
        args.cpus,
        if args.gpus_per_task > 0 {
            " and 1 GPU"
        } else {
            ""
        },
        args.time
    )?;
    writeln!(o, "  {}  the merge job", dir.join("merge.sbatch").display())?;
    writeln!(
        o,
        "  {}  submits both (merge afterok the array)",
        dir.join("submit.sh").display()
    )?;
    writeln!(o, "  submit: bash {}", dir.join("submit.sh").display())?;
    writeln!(o, "  result: {}", job.merged().display())?;
    Ok(())
}

/// `--gpus-per-task`: 0, or 1 for a study the CUDA kernel covers.
fn check_gpus(gpus: usize, spec: &StudySpec, plan: &Plan) -> anyhow::Result<()> {
    if gpus > 1 {
        return Err(BadInput(format!(
            "--gpus-per-task {gpus}: vshake runs one GPU per task; for more GPUs use more \
             --shards with --gpus-per-task 1"
        ))
        .into());
    }
    let names: Vec<String> = spec.excitations.iter().map(|e| e.name.clone()).collect();
    match plan.engine_unsupported(&names) {
        Some(why) if gpus == 1 => Err(BadInput(format!(
            "--gpus-per-task 1: this study cannot run on the GPU: {why}"
        ))
        .into()),
        _ => Ok(()),
    }
}

/// Checks the study and the options, and makes the job's folders.
fn prepare(args: &SlurmArgs) -> anyhow::Result<Job<'_>> {
    let spec = load_study(&args.file)?;
    let base = args.file.parent().unwrap_or(Path::new("."));
    let plan = plan_for(&spec, base)?;
    if args.shards == 0 {
        return Err(BadInput("--shards must be at least 1".into()).into());
    }
    // Every shard must be a valid slice (the same check `study run --shard` makes).
    Shard::parse(
        &format!("{}/{}", args.shards - 1, args.shards),
        plan.samples(),
    )
    .map_err(|e| BadInput(e.to_string().replace("--shard", "--shards")))?;
    if args.cpus == 0 {
        return Err(BadInput("--cpus must be at least 1".into()).into());
    }
    check_gpus(args.gpus_per_task, &spec, &plan)?;
    slurm_value("time", &args.time)?;
    let mut common = String::new();
    for (flag, v) in [("partition", &args.partition), ("account", &args.account)] {
        if let Some(v) = v {
            slurm_value(flag, v)?;
            common += &format!("#SBATCH --{flag}={v}\n");
        }
    }
    let name: String = spec
        .name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let dir = args
        .dir
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("slurm_{name}")));
    for d in ["logs", "shards"] {
        std::fs::create_dir_all(dir.join(d))
            .with_context(|| format!("cannot create {}", dir.join(d).display()))?;
    }
    let dir = absolute(&dir)?;
    if dir.to_string_lossy().chars().any(|c| "\"$`\\".contains(c)) {
        return Err(BadInput(format!(
            "--dir {}: the path may not contain \" $ ` or \\ (it goes into the job scripts)",
            dir.display()
        ))
        .into());
    }
    let bin = match &args.bin {
        Some(b) => absolute(b)?,
        None => std::env::current_exe().context("locating the study executable")?,
    };
    Ok(Job {
        args,
        name,
        samples: plan.samples(),
        excitations: plan.references.len(),
        dir,
        study: absolute(&args.file)?,
        bin,
        common,
    })
}

impl Job<'_> {
    fn merged(&self) -> PathBuf {
        self.dir.join(format!("{}.parquet", self.name))
    }
}

/// The job array: task I runs shard I/N, stops before the time limit, requeues and resumes.
fn array_script(job: &Job<'_>) -> String {
    let (args, name, dir, common, n) =
        (job.args, &job.name, &job.dir, &job.common, job.args.shards);
    let shard_out = dir.join("shards").join(format!(
        "{name}.shard-${{SLURM_ARRAY_TASK_ID}}-of-{n}.parquet"
    ));
    // Slurm sends SIGTERM to the batch shell 5 minutes before the time limit (--signal=B:TERM@300);
    // the shell passes it on to `study`, which finishes the chunks in flight, closes its file
    // marked incomplete and exits with 143; the task then requeues itself, and the requeued task
    // (or one requeued after preemption or a node failure) continues with --resume.
    format!(
        "#!/bin/bash\n\
# Written by `study slurm` (vshake {ver}): {samples} samples x {exc} excitations of {study} in {n} shards.\n\
# Task I runs `study run --shard I/{n}`, a contiguous slice of the design; the merge job joins them.\n\
# Near the time limit the task stops cleanly and requeues itself; a requeued task resumes its shard.\n\
#SBATCH --job-name=vshake-{name}\n\
#SBATCH --array=0-{last}\n\
#SBATCH --ntasks=1\n\
#SBATCH --cpus-per-task={cpus}\n\
{gpus}#SBATCH --time={time}\n\
#SBATCH --signal=B:TERM@300\n\
#SBATCH --requeue\n\
#SBATCH --open-mode=append\n\
{common}#SBATCH --output={logs}/shard-%a.out\n\
set -uo pipefail\n\
out=\"{shard_out}\"\n\
partial=\"${{out%.parquet}}.partial.parquet\"\n\
threads=\"${{SLURM_CPUS_PER_TASK:-{cpus}}}\"\n\
if [ -e \"$out\" ] || [ -e \"$partial\" ] || [ -e \"$partial.tmp.checkpoint\" ] || [ -e \"$partial.killed\" ]; then\n\
  {bin} run --resume \"$out\" --threads \"$threads\"{backend} --log-progress &\n\
else\n\
  {bin} run {study_q} --shard \"${{SLURM_ARRAY_TASK_ID}}/{n}\" --threads \"$threads\"{backend} --log-progress --out \"$out\" &\n\
fi\n\
pid=$!\n\
trap 'kill -TERM \"$pid\" 2>/dev/null' TERM\n\
wait \"$pid\"; status=$?\n\
# wait returns early when the trap runs: wait again for study to close its file.\n\
while kill -0 \"$pid\" 2>/dev/null; do wait \"$pid\"; status=$?; done\n\
if [ \"$status\" -eq 143 ]; then\n\
  echo \"stopped before the time limit; requeueing to resume\"\n\
  scontrol requeue \"${{SLURM_ARRAY_JOB_ID}}_${{SLURM_ARRAY_TASK_ID}}\"\n\
fi\n\
exit \"$status\"\n",
        ver = env!("CARGO_PKG_VERSION"),
        samples = job.samples,
        exc = job.excitations,
        study = job.study.display(),
        last = n - 1,
        cpus = args.cpus,
        gpus = match args.gpus_per_task {
            0 => String::new(),
            g => format!("#SBATCH --gpus-per-task={g}\n"),
        },
        backend = if args.gpus_per_task > 0 { " --backend cuda" } else { "" },
        time = args.time,
        logs = dir.join("logs").display(),
        bin = q(&job.bin),
        study_q = q(&job.study),
        shard_out = shard_out.display(),
    )
}

/// The merge job: joins the shards once every array task has succeeded.
fn merge_script(job: &Job<'_>) -> String {
    let (name, dir, common, n) = (&job.name, &job.dir, &job.common, job.args.shards);
    let merged = job.merged();
    format!(
        "#!/bin/bash\n\
# Written by `study slurm`: joins the {n} shards once every array task has succeeded.\n\
#SBATCH --job-name=vshake-{name}-merge\n\
#SBATCH --ntasks=1\n\
#SBATCH --cpus-per-task=1\n\
#SBATCH --time=00:30:00\n\
{common}#SBATCH --output={logs}/merge.out\n\
set -euo pipefail\n\
exec {bin} merge {shards} --out {merged}\n",
        logs = dir.join("logs").display(),
        bin = q(&job.bin),
        shards = q(&dir.join("shards")),
        merged = q(&merged),
    )
}

/// The submit script: the array, then the merge job after it (afterok).
fn submit_script(job: &Job<'_>) -> String {
    let (dir, n, merged) = (&job.dir, job.args.shards, job.merged());
    format!(
        "#!/bin/bash\n\
# Submits the array, then the merge job to run after all of its tasks succeed (afterok).\n\
set -euo pipefail\n\
array=$(sbatch --parsable {array_q})\n\
array=${{array%%;*}}\n\
merge=$(sbatch --parsable --dependency=afterok:${{array}} {merge_q})\n\
merge=${{merge%%;*}}\n\
echo \"submitted array job ${{array}} ({n} tasks) and merge job ${{merge}} (afterok:${{array}})\"\n\
echo \"merged table when done: {merged}\"\n",
        array_q = q(&dir.join("array.sbatch")),
        merge_q = q(&dir.join("merge.sbatch")),
        merged = merged.display(),
    )
}
