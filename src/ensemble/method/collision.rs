//! `method = "collision"`: collisions of two fragments, set up by `[collision]`
//! ([`crate::ensemble::collision_scene`]) and run by their own runner
//! ([`crate::ensemble::collision_run`]), not through a sampler of the ensemble runner.

use std::convert::Infallible;

use serde::Deserialize;

use super::{Binding, BoundSampler, Context, Method};
use crate::ensemble::collision_scene::{CollisionScene, parse_collision};
use crate::runtime::Molecule;
use crate::runtime::diagnostic::FileError;
use crate::runtime::sample::{SampleError, Sampler};

/// The collision method takes no key of `[ensemble]` of its own (its settings are `[collision]`).
#[derive(Deserialize)]
pub struct Keys {}

/// Collisions of two fragments.
#[derive(Clone, Debug)]
pub struct Collision(pub Box<CollisionScene>);

impl Method for Collision {
    const NAME: &'static str = "collision";
    type Keys = Keys;
    type Bound<const N: usize> = Infallible;

    fn read(_: Keys, cx: &Context<'_>) -> Result<Self, FileError> {
        if let Some(k) = &cx.common().keep_trajectories {
            return Err(cx.src().error(
                k.span(),
                "`keep_trajectories` does not apply to a collision ensemble (it writes final_states.csv)",
                "remove keep_trajectories; run one collision with `rovib run` and [initial] positions to see its path",
            ));
        }
        Ok(Collision(Box::new(parse_collision(cx.scene(), cx.method_span())?)))
    }

    fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        _m: &M,
        cx: &Binding<'_>,
    ) -> Result<(Infallible, String), FileError> {
        Err(cx.src().error(
            cx.method_span(),
            "a collision ensemble runs through `rovib ensemble` (its own runner), not with another sampler",
            "run the scene with `rovib ensemble`",
        ))
    }
}

/// A collision ensemble is never bound to a sampler ([`Collision::bind`] refuses).
impl<const N: usize> BoundSampler<N> for Infallible {
    fn sampler<'m, M: Molecule<N, NA> + Sync, const NA: usize>(
        &self,
        _m: &'m M,
        _seed: u64,
    ) -> Result<Box<dyn Sampler<N> + 'm>, SampleError> {
        match *self {}
    }
}
