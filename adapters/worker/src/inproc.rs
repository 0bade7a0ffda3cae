//! `inproc`: the ceiling without IPC — the same envs, split over threads as they would be
//! over workers, stepped through the same batch code straight into local buffers.

use crate::serve::make_envs;
use anyhow::Context;
use envhub_shm::{BatchLayout, ServedBatch, WorkerJob, env_flag};
use rand::SeedableRng;
use std::time::Instant;

/// Distinct random action batches cycled through (sampling is not what is measured).
const ACTION_POOL: usize = 64;

pub(crate) fn run(job_json: &str, threads: usize, steps: usize) -> anyhow::Result<()> {
    let job: WorkerJob = serde_json::from_str(job_json).context("invalid job")?;
    let threads = threads.clamp(1, job.worker_envs.max(1));
    let barrier = std::sync::Barrier::new(threads + 1);
    let (total, seconds) = std::thread::scope(|scope| -> anyhow::Result<(usize, f64)> {
        let mut handles = Vec::new();
        for t in 0..threads {
            let mut part = job.clone();
            part.worker_envs =
                job.worker_envs / threads + usize::from(t < job.worker_envs % threads);
            let barrier = &barrier;
            handles.push(scope.spawn(move || -> Result<usize, String> {
                let (mut batch, spec) = make_envs(&part)?;
                let n = part.worker_envs;
                let layout = BatchLayout::new(n, spec.observation_space.byte_len(), false);
                let mut words = vec![0u64; layout.size() / 8 + 1];
                let flags = vec![env_flag::SELECTED; n];
                let seeds: Vec<u64> = (0..n as u64).collect();
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(t as u64);
                let actions: Vec<Vec<u8>> = (0..ACTION_POOL)
                    .map(|_| {
                        (0..n)
                            .flat_map(|_| spec.action_space.sample(&mut rng))
                            .collect()
                    })
                    .collect();
                // SAFETY: `words` holds a whole slot, 8-byte aligned, used by this thread only.
                let mut out = unsafe { layout.rows_mut(words.as_mut_ptr().cast(), 0, n) };
                let seeded = vec![env_flag::SELECTED | env_flag::SEEDED; n];
                batch
                    .reset(&seeded, &seeds, &Default::default(), &mut out)
                    .map_err(|e| e.to_string())?;
                barrier.wait();
                for s in 0..steps {
                    batch
                        .step(&flags, &actions[s % ACTION_POOL], &mut out)
                        .map_err(|e| e.to_string())?;
                }
                Ok(n * steps)
            }));
        }
        barrier.wait();
        let start = Instant::now();
        let mut total = 0;
        for h in handles {
            total += h
                .join()
                .map_err(|_| anyhow::anyhow!("a stepping thread panicked"))?
                .map_err(anyhow::Error::msg)?;
        }
        Ok((total, start.elapsed().as_secs_f64()))
    })?;
    println!(
        "{}",
        serde_json::json!({"steps": total, "seconds": seconds, "steps_per_sec": total as f64 / seconds})
    );
    Ok(())
}
