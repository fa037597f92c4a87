"""``nbrdf project``: fit a material code (3 x 34: body latents and clear coat)
to a material, to measured samples or to a MERL table, optionally adapting a
copy of the decoder."""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass

from nbrdf.cli.common import at_least, decoder_or_default, out_path
from nbrdf.cli.config import add_arguments, build
from nbrdf.neural.errors import NbrdfError
from nbrdf.neural.material import RANGES, load_material


@dataclass
class ProjectConfig:
    """``nbrdf project``: exactly one source (--material, --samples or --merl) -> a latent file."""

    out: str
    """latent .safetensors"""
    material: str | None = None
    """material JSON (fitted through its reference)"""
    samples: str | None = None
    """float (N, 9) .npy: wi.xyz, wo.xyz, f.rgb"""
    merl: str | None = None
    """MERL .binary file"""
    decoder: str | None = None
    """decoder weights (default: the shipped ones)"""
    finetune: bool = False
    """measured files: also adapt a copy of the decoder"""
    coat: str | None = None
    """--samples: ROUGHNESS,IOR of the clear coat on top of the sampled BRDF, kept exact in the code
    (a material's coat is read from its top layer; default: none)"""
    pairs: int = 2048
    """samples drawn from the material or table"""
    spp: int = 64
    """Monte Carlo paths per pair for a stack's reference"""
    steps: int = 400
    """optimisation steps of the projection"""
    seed: int = 0
    """random seed of the samples and the projection"""


def cmd_project(a: argparse.Namespace) -> int:
    from nbrdf.neural import decoder, latent, projection  # late: torch costs ~1 s, --help needs none
    from nbrdf.training import project as pj  # late: torch and the walk, as above

    c: ProjectConfig = build(ProjectConfig, a)
    out = out_path(c.out, (".safetensors",))
    given = [x for x in (c.material, c.samples, c.merl) if x]
    if len(given) != 1:
        raise NbrdfError("give exactly one of --material, --samples, --merl")
    at_least("--steps", c.steps)
    dec = decoder_or_default(c.decoder)
    if c.material:
        s = pj.material_samples(load_material(c.material), n=c.pairs, spp=c.spp, seed=c.seed)
        source = {"material": str(c.material), "spp": c.spp, "pairs": c.pairs}
    elif c.samples:
        s = pj.npy_samples(c.samples, coat=_coat_arg(c.coat) if c.coat else None)
        source = {"samples": str(c.samples)}
        if s.coat is not None:
            source["coat"] = s.coat.tolist()
    elif c.merl:
        s = pj.merl_samples(c.merl, n=c.pairs, seed=c.seed)
        source = {"merl": str(c.merl), "pairs": c.pairs}
    if c.coat and not c.samples:
        raise NbrdfError("--coat: only with --samples (a material's coat is its top layer; a MERL table has none)")
    if c.finetune and not c.merl:
        raise NbrdfError("--finetune: only for measured (--merl) files")
    lat, secs = pj.project_to_latent(dec, s, source, projection.ProjectionConfig(steps=c.steps))
    report = {"out": str(out), "decoder_id": lat.decoder_id, "sample_seconds": round(s.seconds, 3),
              "projection_seconds": round(secs, 3)}
    if c.finetune:
        t0 = time.perf_counter()
        tuned, z = pj.finetune(dec, s, lat.z)
        dec_path = out.with_name(out.stem + ".decoder.safetensors")
        lat.decoder_id = decoder.save_decoder(tuned, dec_path, trained_on={"finetuned_from": dec.weights_id(),
                                                                           "merl": str(c.merl)})
        lat.z = z
        lat.source["finetuned_decoder"] = dec_path.name
        report.update(finetune_seconds=round(time.perf_counter() - t0, 3), decoder=str(dec_path),
                      decoder_id=lat.decoder_id)
    latent.save_latent(out, lat)
    print(json.dumps(report))
    return 0


def _coat_arg(text: str) -> tuple[float, float]:
    """``--coat ROUGHNESS,IOR``, checked against the material ranges."""
    try:
        r, ior = (float(x) for x in text.split(","))
    except ValueError:
        raise NbrdfError(f"--coat: {text!r} is not ROUGHNESS,IOR (e.g. 0.02,1.5)") from None
    (rlo, rhi), (ilo, ihi) = RANGES["roughness"], RANGES["ior"]
    if not (rlo <= r <= rhi and ilo <= ior <= ihi):
        raise NbrdfError(f"--coat: roughness must lie in [{rlo:g}, {rhi:g}] and ior in [{ilo:g}, {ihi:g}]")
    return r, ior


def register(sub: argparse._SubParsersAction) -> None:
    """Adds ``project`` to the ``nbrdf`` subcommands."""
    p = sub.add_parser("project", help="fit a material code (3 x 34) to a material, samples or a MERL table",
                       description=ProjectConfig.__doc__)
    add_arguments(p, ProjectConfig)
    p.set_defaults(fn=cmd_project)
