"""Trained SB3 models as residual policies: loading, and running them in the diagram.

A policy saved by ``rlfd train`` is a Stable-Baselines3 zip (PPO, SAC, TD3 or
sb3-contrib's RecurrentPPO). :class:`DeployedPolicy` turns it into the callable the
diagram's ``ResidualPolicy`` runs at 10 Hz: obs (26,) -> action (6,), keeping the
observation history of frame-stacked models and the LSTM state of recurrent ones.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from rlfd_drake.control_math import RESIDUAL_MODES, RESIDUAL_PARTS, pad_residual_part
from rlfd_drake.paths import shipped_path

#: Algorithm name -> (module, class) of its SB3 implementation.
SB3_CLASSES = {
    "ppo": ("stable_baselines3", "PPO"),
    "sac": ("stable_baselines3", "SAC"),
    "td3": ("stable_baselines3", "TD3"),
    "recurrent_ppo": ("sb3_contrib", "RecurrentPPO"),
}


#: The folders of a run where ``rlfd train`` saves policies besides ``policy.zip``.
RUN_SUBFOLDERS = ("checkpoints", "eval")


def checkpoint_steps(path: str | Path) -> int:
    """The training steps of a checkpoint SB3 saved as ``<prefix>_<steps>_steps.zip``."""
    return int(Path(path).stem.split("_")[-2])


def _sb3_kind_from_zip(path: Path) -> str | None:
    """The algorithm of an SB3 zip from its policy class module, or None if unclear."""
    try:
        with zipfile.ZipFile(path) as z:
            data = json.loads(z.read("data"))
    except (KeyError, OSError, ValueError, zipfile.BadZipFile):
        return None
    module = str(data.get("policy_class", {}).get("__module__", ""))
    if "recurrent" in module:
        return "recurrent_ppo"
    if ".sac." in module:
        return "sac"
    if ".td3." in module:
        return "td3"
    if module in ("stable_baselines3.common.policies", "rlfd_drake.privileged_critic"):
        return "ppo"
    return None


def _split_spec(spec: str | Path) -> tuple[str | None, str]:
    """(kind, path) of a saved-model spec ``path`` or ``kind:path`` (kind None if not
    given as one of SB3_CLASSES)."""
    kind, _, rest = str(spec).partition(":")
    return (kind, rest) if rest and kind in SB3_CLASSES else (None, str(spec))


def policy_file(spec: str | Path) -> Path:
    """The file of a saved-model spec ``path`` or ``kind:path`` (kind in SB3_CLASSES);
    a ``models/...`` path not found here is the installed package's (``shipped_path``)."""
    return shipped_path(_split_spec(spec)[1])


def existing_policy_file(spec: str | Path) -> Path:
    """:func:`policy_file`, refused with a ValueError naming it if it is not a file."""
    path = policy_file(spec)
    if not path.is_file():
        problem = "is a folder, not a saved policy" if path.is_dir() else "does not exist"
        raise ValueError(f"policy file {str(path)!r} {problem}")
    return path


def load_sb3_model(spec: str | Path):
    """Loads a saved SB3 model from ``path`` or ``kind:path`` (kind in SB3_CLASSES).

    Returns:
        (model, kind). The model is loaded on the CPU.

    Raises:
        ValueError: no such file, or no SB3 class could load it.
    """
    path = existing_policy_file(spec)
    kind = _split_spec(spec)[0]
    if kind is not None:
        kinds = [kind]
    else:
        detected = _sb3_kind_from_zip(path)
        kinds = [detected] if detected else list(SB3_CLASSES)
    import importlib

    errors = []
    for k in kinds:
        module_name, class_name = SB3_CLASSES[k]
        cls = getattr(importlib.import_module(module_name), class_name)
        try:
            return cls.load(str(path), device="cpu"), k
        except Exception as e:  # noqa: BLE001 - any loader error means "not this class"
            errors.append(f"{class_name}: {type(e).__name__}: {e}")
    raise ValueError(f"could not load {path} as an SB3 model: " + "; ".join(errors))


def _optimizers(model) -> list:
    """The torch optimizers an SB3 model saves with its parameters."""
    found = []
    for owner in (model.policy, getattr(model, "actor", None), getattr(model, "critic", None)):
        optimizer = getattr(owner, "optimizer", None) if owner is not None else None
        if optimizer is not None and all(optimizer is not f for f in found):
            found.append(optimizer)
    entropy = getattr(model, "ent_coef_optimizer", None)
    if entropy is not None:
        found.append(entropy)
    return found


#: The parts of the residual each composer mode corrects.
_MODE_PARTS = {
    mode: {part for part in ("translation", "orientation") if mode in (part, "full")}
    for mode in RESIDUAL_MODES
}


def training_config_file(policy_path: str | Path) -> Path | None:
    """The training configuration saved with a policy: ``<name>.json`` beside it (what
    ``rlfd export`` writes), the run folder's ``config.json`` beside a ``policy.zip``,
    or above a checkpoint or best model in the run's ``checkpoints/`` or ``eval/``
    folder; None if there is none."""
    path = policy_file(policy_path)
    if path.with_suffix(".json").exists():
        return path.with_suffix(".json")
    if path.name == "policy.zip" and path.with_name("config.json").exists():
        return path.with_name("config.json")
    if path.parent.name in RUN_SUBFOLDERS and (path.parent.parent / "config.json").exists():
        return path.parent.parent / "config.json"
    return None


def trained_config_value(policy_path: str | Path, key: str):
    """A field of the training configuration saved with a policy (see
    :func:`training_config_file`), or None if there is none or it lacks the field."""
    config_file = training_config_file(policy_path)
    if config_file is None:
        return None
    try:
        return json.loads(config_file.read_text())["config"][key]
    except (KeyError, TypeError, ValueError):
        return None  # not a training configuration


def trained_residual_mode(policy_path: str | Path) -> str | None:
    """The ``residual_mode`` a policy was trained with, from its training configuration
    (see :func:`training_config_file`), or None if unknown."""
    mode = trained_config_value(policy_path, "residual_mode")
    return mode if mode in _MODE_PARTS else None


def trained_base_correction(policy_path: str | Path) -> str | None:
    """The hand-written rule a policy was trained on top of (``rlfd train
    --base-correction``), or None (the DMP alone, or unknown)."""
    name = trained_config_value(policy_path, "base_correction")
    return name if isinstance(name, str) else None


def check_residual_mode(policy_path: str | Path, residual_mode: str) -> None:
    """Refuses to run a policy in a mode that applies parts of the residual it was not
    trained to set (e.g. a translation-only policy in "full" mode: its untrained
    orientation outputs would tilt the part). A policy whose training configuration is
    unknown is not checked.

    Raises:
        ValueError: ``residual_mode`` is unknown or corrects a part the policy was not
            trained on.
    """
    if residual_mode not in _MODE_PARTS:
        raise ValueError(
            f"residual_mode must be one of {sorted(_MODE_PARTS)}, got {residual_mode!r}"
        )
    trained = trained_residual_mode(policy_path)
    if trained is None:
        return
    extra = _MODE_PARTS[residual_mode] - _MODE_PARTS[trained]
    if extra:
        raise ValueError(
            f"residual_mode {residual_mode!r} applies the {' and '.join(sorted(extra))} of "
            f"{policy_path}, which was trained with residual_mode {trained!r} "
            f"({training_config_file(policy_path)}); use residual mode {trained!r}"
        )


def export_policy(source: str | Path, destination: str | Path, overwrite: bool = False) -> Path:
    """Writes a deployment copy of a trained SB3 model: the same networks (so the same
    actions) without the optimizers' moment estimates, which are as large as the
    networks and only matter for continuing training (use the run folder's
    checkpoints for that). The run's training configuration, if any, is copied beside
    it as ``<destination stem>.json``.

    Raises:
        FileExistsError: ``destination`` exists and ``overwrite`` is False.
    """
    destination = Path(destination)
    if destination.exists() and not overwrite:
        raise FileExistsError(f"{destination} exists; pass overwrite=True to replace it")
    if destination.suffix != ".zip":
        raise ValueError(f"destination must end in .zip, got {str(destination)!r}")
    config_file = training_config_file(source)
    sidecar = destination.with_suffix(".json")
    if config_file is not None and sidecar.exists() and not overwrite:
        raise FileExistsError(f"{sidecar} exists; pass overwrite=True to replace it")
    model, _ = load_sb3_model(source)
    for optimizer in _optimizers(model):
        optimizer.state.clear()
    model.save(destination)
    if config_file is not None:
        # The training configuration travels with the policy (its residual mode above all).
        sidecar.write_text(config_file.read_text())
    return destination


class DeployedPolicy:
    """A trained SB3 model as the residual policy inside the diagram: obs (26,) ->
    action (6,).

    * Frame-stacked models (SAC with history): the last observations are kept exactly
      as ``VecFrameStack`` does (zeros before the first, newest last).
    * Recurrent models (RecurrentPPO): the LSTM state is kept between calls.
    * A model with a 3-D action (translation-only or orientation-only training) is
      padded with zeros according to ``residual_mode``.
    * ``reset()`` (called by ResidualPolicy at every initialisation) starts an episode.
    * ``deterministic=False`` samples from the policy's distribution; ``reset()`` then
      seeds torch with ``seed`` so the episode is reproducible. ``noise_scale``
      multiplies the distribution's standard deviation when sampling (1: the trained
      distribution, as SB3 samples it; 0 < s < 1: between the mean action and the
      trained exploration, a temperature for the success-against-force trade-off).
      Scales other than 1 are for SAC (the Gaussian before its tanh) and PPO (the
      Gaussian, clipped to the action space as SB3 clips it).
    """

    def __init__(
        self,
        model,
        residual_mode: str = "full",
        deterministic: bool = True,
        observation_size: int = 26,
        seed: int = 0,
        noise_scale: float = 1.0,
    ):
        check_noise_scale(noise_scale)
        model_size = int(model.observation_space.shape[0])
        # A privileged critic's model (privileged_critic.py) takes entries that the
        # diagram does not observe and its actor does not read: they are padded zeros.
        stacked = int(getattr(model.policy, "actor_observation_size", model_size))
        self._privileged_padding = np.zeros(model_size - stacked, dtype=np.float32)
        if stacked % observation_size:
            raise ValueError(
                f"the model's observation size {stacked} is not a multiple of the "
                f"diagram's observation size {observation_size}"
            )
        self.model = model
        self.history = stacked // observation_size
        self.observation_size = observation_size
        self.residual_mode = residual_mode
        self.deterministic = deterministic
        self.seed = int(seed)
        self._recurrent = hasattr(model.policy, "lstm_actor")
        self.noise_scale = float(noise_scale)
        self._scaled_sampling = not deterministic and self.noise_scale != 1.0
        if self._scaled_sampling and (self._recurrent or not _samples_a_gaussian(model)):
            raise ValueError(
                f"noise_scale {noise_scale} needs a SAC or PPO policy; "
                f"{type(model).__name__} (or state-dependent noise) samples only at its "
                "trained scale"
            )
        self.reset()

    def reset(self) -> None:
        """New episode: clears the observation history and the recurrent state."""
        self._stack = np.zeros(self.history * self.observation_size, dtype=np.float32)
        self._lstm_state = None
        self._episode_start = np.ones((1,), dtype=bool)
        if not self.deterministic:
            # SB3 samples with torch's global generator: seed it per episode so a
            # stochastic evaluation is reproducible.
            import torch

            torch.manual_seed(self.seed)

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        obs = np.asarray(observation, dtype=np.float32)
        self._stack = np.roll(self._stack, -self.observation_size)
        self._stack[-self.observation_size :] = obs
        model_input = self._stack
        if self._privileged_padding.size:
            model_input = np.concatenate([self._stack, self._privileged_padding])
        if self._recurrent:
            action, self._lstm_state = self.model.predict(
                self._stack[None],
                state=self._lstm_state,
                episode_start=self._episode_start,
                deterministic=self.deterministic,
            )
            self._episode_start = np.zeros((1,), dtype=bool)
        elif self._scaled_sampling:
            action = self._sample_scaled(model_input)
        else:
            action, _ = self.model.predict(model_input, deterministic=self.deterministic)
        action = np.asarray(action, dtype=float).reshape(-1)
        if action.size == 3 and self.residual_mode in RESIDUAL_PARTS:
            return pad_residual_part(action, self.residual_mode)
        return action

    def _sample_scaled(self, stacked_observation: np.ndarray) -> np.ndarray:
        """One action sampled with the policy's standard deviation times noise_scale,
        mapped to the action space as SB3's ``predict`` maps its samples."""
        import torch

        policy = self.model.policy
        obs, _ = policy.obs_to_tensor(stacked_observation)
        with torch.no_grad():
            if hasattr(policy, "actor"):  # SAC: a Gaussian squashed by tanh
                mean, log_std, _ = policy.actor.get_action_dist_params(obs)
                noise = torch.randn(mean.shape, dtype=mean.dtype)
                action = torch.tanh(mean + self.noise_scale * log_std.exp() * noise)
            else:  # PPO: a Gaussian, clipped below
                gaussian = policy.get_distribution(obs).distribution
                noise = torch.randn(gaussian.mean.shape, dtype=gaussian.mean.dtype)
                action = gaussian.mean + self.noise_scale * gaussian.stddev * noise
        action = action.numpy().reshape(self.model.action_space.shape)
        if policy.squash_output:
            return policy.unscale_action(action)
        return np.clip(action, self.model.action_space.low, self.model.action_space.high)


class MeanOfPolicies:
    """Several residual policies acting as one: the mean of their actions.

    An ensemble of training seeds' policies: one run's mean action fails some starts
    that most other seeds insert (results/full_pose_study.md, section 18), and the mean
    of their actions is a policy that can be run. Each member keeps its own observation
    history; ``reset()`` resets them all.
    """

    def __init__(self, members: list):
        if len(members) < 2:
            raise ValueError(f"an ensemble needs at least 2 policies, got {len(members)}")
        self.members = list(members)

    def reset(self) -> None:
        for member in self.members:
            member.reset()

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return np.mean([member(observation) for member in self.members], axis=0)


def check_noise_scale(noise_scale: float) -> None:
    """Raises a ValueError unless ``noise_scale`` is a finite number > 0."""
    if not (isinstance(noise_scale, int | float) and np.isfinite(noise_scale) and noise_scale > 0):
        raise ValueError(f"noise_scale must be a number > 0, got {noise_scale!r}")


def _samples_a_gaussian(model) -> bool:
    """Whether ``model`` samples a plain Gaussian whose std can be scaled: SAC's actor
    or PPO's policy, without state-dependent (gSDE) noise."""
    sac_actor = getattr(model.policy, "actor", None)
    if hasattr(sac_actor, "get_action_dist_params"):
        return not sac_actor.use_sde
    return hasattr(model.policy, "get_distribution") and not model.policy.use_sde
