"""The environments. Importing this package registers the Gymnasium id ``roshan/FlyAgent-v0``, as Gymnasium's own
env packages do: ``gymnasium.make("roshan/FlyAgent-v0")`` gives a :class:`roshan.env.single.FlyEnv` and
``gymnasium.make_vec(..., num_envs=E)`` a :class:`roshan.env.fly.FlyVectorEnv` (keyword arguments go to those
constructors). In a process that has not imported it, ``gymnasium.make("roshan.env:roshan/FlyAgent-v0")`` imports
it first. Registering imports neither Taichi nor torch."""

import gymnasium

FLY_AGENT_ID = "roshan/FlyAgent-v0"

# A reload (or a second import path) must not re-register: gymnasium warns when an id is overridden. No
# max_episode_steps: the env ends its own episodes (T_max of the agents' model), and make_vec would pass it on to
# FlyVectorEnv, which takes no such argument.
if FLY_AGENT_ID not in gymnasium.registry:
    gymnasium.register(id=FLY_AGENT_ID, entry_point="roshan.env.single:FlyEnv",
                       vector_entry_point="roshan.env.fly:FlyVectorEnv")
