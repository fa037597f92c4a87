"""Names vulture (tests/test_architecture.py's dead-code check) cannot see used: each is read by a library or a
protocol, not by the project's code. A name goes here only with the reason; anything else unused is removed."""
# ruff: noqa
# pyright: basic
from types import SimpleNamespace

_ = SimpleNamespace()

# moderngl objects: setting these attributes is the GL call (texture wrap, context state, blending).
_.repeat_x, _.repeat_y, _.repeat_z, _.anisotropy
_.depth_func, _.blend_func, _.color_mask, _.depth_mask, _.scissor
# imgui's IO configuration, read by imgui itself.
_.config_input_trickle_event_queue
# argparse reads a sub-parser's description.
_.description
# Mitsuba 3 reads these from a BSDF plug-in (flags, sampled lobe) and calls these overrides.
_.m_flags, _.sampled_component, _.sampled_type, _.traverse, _.to_string
# torch.nn.Module.__call__ calls forward.
_.forward
# neural/brdf.py: the one BRDF interface (a typing.Protocol) analytic, Monte Carlo and neural BRDFs implement.
_.BRDF
# dataclass fields written out whole (dataclasses.asdict into a bench / report JSON) or read through getattr.
_.p99, _.seconds_per_render, _.cpu_seconds_per_render, _.cpu_seconds
# functools.lru_cache key: a file's modification time makes an edited file miss the cache.
mtime_ns
# MaterialX's shader generator reads its GenOptions; moderngl reads the context's point size (viewer/gpu/materialx_glsl.py).
_.hwSpecularEnvironmentMethod, _.hwMaxActiveLightSources, _.point_size
