"""ROSHAN-Taichi: batched FireSPIN wildfire simulation and hierarchical RL for UAV fire fighting.

Importing the package registers the Gymnasium id ``roshan/FlyAgent-v0``: ``gymnasium.make`` gives a
:class:`roshan.env.single.FlyEnv` and ``gymnasium.make_vec(..., num_envs=E)`` a
:class:`roshan.env.fly.FlyVectorEnv` (keyword arguments go to those constructors). Entry points are strings, so
registering imports neither Taichi nor torch. Importing it also makes glibc keep freed memory for reuse
(:mod:`roshan.allocator`: large torch temporaries were page-faulted in again on every step).
"""

from roshan import allocator

__version__ = "0.1.0"

FLY_AGENT_ID = "roshan/FlyAgent-v0"


def _register_envs() -> None:
    import gymnasium

    # A reload (or a second import path) must not re-register: gymnasium warns when an id is overridden.
    if FLY_AGENT_ID in gymnasium.registry:
        return
    # No max_episode_steps: the env ends its own episodes (T_max of agents.md 5), and make_vec would pass it on
    # to FlyVectorEnv, which takes no such argument.
    gymnasium.register(id=FLY_AGENT_ID, entry_point="roshan.env.single:FlyEnv",
                       vector_entry_point="roshan.env.fly:FlyVectorEnv")


_register_envs()
allocator.retain_freed_memory()
