"""The simulated arms as Gymnasium environments, on the control layer (`bodyschema.control`), and baseline policies.

    import gymnasium, bodyschema.envs                       # importing registers the ids below
    from bodyschema.evaluation.reaching import AIFPolicy    # the reaching benchmark's agent, on the env
    env = gymnasium.make("bodyschema/Reach-nao_arm-v0")     # or ReachEnv(robot="ur5.toml", goal="ee_pixel", ...)
    scores = bodyschema.envs.compare(env, {"random": RandomPolicy(env), "aif": AIFPolicy(env)}, episodes=10)

Ids: bodyschema/Reach-<robot>-v0 per shipped robot, and bodyschema/Reach-v0 (pass robot=<a name or file>).
`ReachEnv` (reach_env.py, spaces in spaces.py), `PDPolicy`, `RandomPolicy` (policies.py), `run_policy` and `compare`
(scores.py); each loaded on first use. envs imports nothing from evaluation/ (tests/test_layering.py).
"""

from __future__ import annotations

from bodyschema.envs.registration import register_envs
from bodyschema.lazy import lazy_exports

register_envs()

__all__, __getattr__, __dir__ = lazy_exports("bodyschema.envs", globals(), {
    "ReachEnv": ("bodyschema.envs.reach_env", "ReachEnv"),
    "PDPolicy": ("bodyschema.envs.policies", "PDPolicy"),
    "RandomPolicy": ("bodyschema.envs.policies", "RandomPolicy"),
    "run_policy": ("bodyschema.envs.scores", "run_policy"), "compare": ("bodyschema.envs.scores", "compare"),
    "PolicyScore": ("bodyschema.envs.scores", "PolicyScore")})
