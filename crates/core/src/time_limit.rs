//! `TimeLimit`: truncation after `max_episode_steps`, the same for every adapter.

use crate::{Env, EnvError, Info, ResetOptions, Space, Transition};

/// Wraps an env and truncates episodes after `max_steps` steps, as Gymnasium's `TimeLimit`.
pub struct TimeLimit<E> {
    inner: E,
    max_steps: Option<u32>,
    elapsed: u32,
}

impl<E: Env> TimeLimit<E> {
    /// Truncates after `max_steps` steps; `None` never truncates.
    pub fn new(inner: E, max_steps: Option<u32>) -> Self {
        TimeLimit {
            inner,
            max_steps,
            elapsed: 0,
        }
    }

    /// Steps taken in the current episode.
    pub fn elapsed(&self) -> u32 {
        self.elapsed
    }
}

impl<E: Env> Env for TimeLimit<E> {
    fn observation_space(&self) -> &Space {
        self.inner.observation_space()
    }

    fn action_space(&self) -> &Space {
        self.inner.action_space()
    }

    fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<(), EnvError> {
        self.elapsed = 0;
        self.inner.reset(seed, options, obs, info)
    }

    fn step(
        &mut self,
        action: &[u8],
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<Transition, EnvError> {
        let mut t = self.inner.step(action, obs, info)?;
        self.elapsed += 1;
        if self.max_steps.is_some_and(|max| self.elapsed >= max) {
            t.truncated = true;
        }
        Ok(t)
    }

    fn render(&mut self) -> Result<Option<(usize, usize, Vec<u8>)>, EnvError> {
        self.inner.render()
    }

    fn render_fps(&self) -> Option<f64> {
        self.inner.render_fps()
    }

    fn close(&mut self) {
        self.inner.close()
    }
}

impl Env for Box<dyn Env> {
    fn observation_space(&self) -> &Space {
        (**self).observation_space()
    }

    fn action_space(&self) -> &Space {
        (**self).action_space()
    }

    fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<(), EnvError> {
        (**self).reset(seed, options, obs, info)
    }

    fn step(
        &mut self,
        action: &[u8],
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<Transition, EnvError> {
        (**self).step(action, obs, info)
    }

    fn render(&mut self) -> Result<Option<(usize, usize, Vec<u8>)>, EnvError> {
        (**self).render()
    }

    fn render_fps(&self) -> Option<f64> {
        (**self).render_fps()
    }

    fn close(&mut self) {
        (**self).close()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An env that only says its frame rate.
    struct Fps(Option<f64>);

    impl Env for Fps {
        fn observation_space(&self) -> &Space {
            unimplemented!()
        }

        fn action_space(&self) -> &Space {
            unimplemented!()
        }

        fn reset(
            &mut self,
            _: Option<u64>,
            _: &ResetOptions,
            _: &mut [u8],
            _: &mut Info,
        ) -> Result<(), EnvError> {
            Ok(())
        }

        fn step(&mut self, _: &[u8], _: &mut [u8], _: &mut Info) -> Result<Transition, EnvError> {
            Ok(Transition::default())
        }

        fn render_fps(&self) -> Option<f64> {
            self.0
        }
    }

    #[test]
    fn wrappers_pass_the_render_fps_on() {
        let boxed: Box<dyn Env> = Box::new(Fps(Some(12.5)));
        assert_eq!(boxed.render_fps(), Some(12.5));
        assert_eq!(TimeLimit::new(boxed, Some(3)).render_fps(), Some(12.5));
        assert_eq!(TimeLimit::new(Fps(None), None).render_fps(), None);
    }
}
