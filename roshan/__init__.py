"""ROSHAN-Taichi: batched FireSPIN wildfire simulation and hierarchical RL for UAV fire fighting.

Importing the package registers the Gymnasium id ``roshan/FlyAgent-v0``: ``gymnasium.make`` gives a
:class:`roshan.env.single.FlyEnv` and ``gymnasium.make_vec(..., num_envs=E)`` a
:class:`roshan.env.fly.FlyVectorEnv` (keyword arguments go to those constructors). Registering imports neither
Taichi nor torch, nor gymnasium itself: where gymnasium is not imported yet, the id is registered the moment it
is (so ``roshan --help`` and a fire-only ``roshan simulate`` never pay for gymnasium and numpy). Importing it also
makes glibc keep freed memory for reuse (:mod:`roshan.allocator`: large torch temporaries were page-faulted in
again on every step), and patches Taichi's kernel definitions as Taichi loads (:mod:`roshan.taichi_patches`).
"""

import importlib.util
import sys

from roshan import allocator, taichi_patches

__version__ = "0.1.0"

FLY_AGENT_ID = "roshan/FlyAgent-v0"


def _register_envs() -> None:
    import gymnasium

    # A reload (or a second import path) must not re-register: gymnasium warns when an id is overridden.
    if FLY_AGENT_ID in gymnasium.registry:
        return
    # No max_episode_steps: the env ends its own episodes (T_max of the agents' model), and make_vec would pass it
    # on to FlyVectorEnv, which takes no such argument.
    gymnasium.register(id=FLY_AGENT_ID, entry_point="roshan.env.single:FlyEnv",
                       vector_entry_point="roshan.env.fly:FlyVectorEnv")


class _AfterImport:
    """A one-shot import hook (a meta path finder and the loader it hands out; importlib.abc's base classes are
    left out because importing them costs 30 ms): finds module ``name`` with the other finders, runs it, then
    calls ``then(module)``. Where the module is loaded already, ``then`` runs at once."""

    def __init__(self, name: str, then):
        self.name, self.then = name, then
        if name in sys.modules:
            then(sys.modules[name])
        else:
            sys.meta_path.insert(0, self)

    def find_spec(self, name, path, target=None):
        if name != self.name:
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)  # the finders after this one
        if spec is None or spec.loader is None:
            return spec
        self.loader, spec.loader = spec.loader, self
        return spec

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module):
        module.__loader__ = module.__spec__.loader = self.loader  # the module keeps its own loader afterwards
        self.loader.exec_module(module)
        self.then(module)


_AfterImport("gymnasium", lambda module: _register_envs())
_AfterImport("taichi.lang.kernel_impl", taichi_patches.patch_kernel_impl)
allocator.retain_freed_memory()
