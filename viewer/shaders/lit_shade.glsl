// The lit object's radiance toward the viewer at one surface point for one
// pass: a directional light, an optional point light and an HDR environment.
// No shadowing: one object under a distant environment. Both lit paths call
// it -- object.frag (fragment fallback) and lit.comp (deferred compute pass) --
// with the same pixel and pass, hence the same random numbers and image.
// Needs common.glsl, the BRDF snippet, sampling.glsl and environment.glsl.
//
// The environment integral, per pass and pixel (viewer/lit_sampling.py):
// - The body (the whole BRDF when it is not split): u_ris_samples decoder
//   samples by resampled importance sampling (ris_body_sample: candidates from
//   the environment CDF and the body's lobe, target the lighting times the
//   body's baked table where the draw has one, else times the lobe sampler's
//   pdf; no decoder); with u_ris_samples 0, one sample each of the environment CDF,
//   the body's lobe and the cosine lobe, balance heuristic (u_strategies = 3
//   drops the cosine lobe; u_one_sample draws one sample from their mixture).
//   Where the body is cheap (the baked table), u_body_every > 0: no resampling,
//   the body at every candidate (every_body_samples, balance heuristic).
// - BRDFs split into a closed-form clear coat and a body (neural materials,
//   NB_SPLIT_COAT): the coat (no decoder; the sharp reflections of the
//   studio's panels) apart, from u_coat_samples samples of its GGX visible
//   normals plus every direction the pass looked up, balance heuristic with
//   the sample counts. No sample lands in the coat and is wasted on the body
//   or the other way round.
// Random numbers: rand3 (common.glsl), one Owen-scrambled Sobol sequence per
// strategy and pixel. u_clamp > 0 clamps one sample's contribution (the
// firefly clamp, see lit_sampling.py; biased, default off).

uniform vec3 u_light_dir;       // toward the light, world space
uniform vec3 u_light_radiance;
uniform int u_point_on;         // 1: a point light too
uniform vec3 u_point_pos;       // world space
uniform vec3 u_point_intensity; // radiant intensity: irradiance I cos / d^2
uniform float u_env_intensity;
uniform int u_env_on;           // 0: the light alone (benchmarks, quick previews)
uniform int u_strategies;  // 4: the light and three environment strategies, 3: without the cosine lobe
                           // (a uniform, so the loop is not unrolled: one call site of the BRDF keeps
                           // the shader small)
uniform int u_one_sample;  // 1: one environment sample per pass from the mixture of the three strategies
                           // (one-sample MIS, balance heuristic): two BRDF evaluations per pass, not four
uniform uint u_seed;         // 0: the default image; others: independent renders (noise measurements)
uniform int u_terms;         // bit mask of the estimator's terms kept (TERM_*; diagnostics), -1: all
uniform int u_coat_samples;  // coat visible-normal samples per pass (split BRDFs)
uniform float u_clamp;       // > 0: a sample's contribution is scaled down to this luminance at most
uniform int u_ris_samples;   // > 0: the body's environment light by resampling, this many decoder samples per pass
uniform int u_ris_candidates;  // candidates per resampled sample (even: half environment, half body lobe)
uniform int u_body_every;      // > 0: no resampling, the body at every candidate, this many of them from its lobe
uniform int u_ris_lobe;        // resampling: > 0, this many of each sample's candidates from the body's lobe
                               // (a contiguous run, the rest from the environment); 0: half, alternating

// Terms of the estimator (u_terms bits), as viewer/lit_sampling.py Term.
const int TERM_LIGHT = 1;      // the directional and the point light
const int TERM_ENV_BODY = 2;   // environment-CDF samples, body (the whole BRDF when not split)
const int TERM_LOBE_BODY = 4;  // the body's lobe (the BRDF's lobe when not split)
const int TERM_COS_BODY = 8;   // cosine-lobe samples, body (the whole BRDF when not split)
const int TERM_ENV_COAT = 16;  // environment-CDF samples, coat
const int TERM_LOBE_COAT = 32; // the coat's visible-normal samples

// Random-number streams (rand3's dim_set), one per strategy.
const uint STREAM_ENV = 0u, STREAM_LOBE = 1u, STREAM_COS = 2u, STREAM_PICK = 3u, STREAM_COAT = 4u;

#ifndef NB_SPLIT_COAT
vec3 body_brdf(vec3 wi, vec3 wo) { return brdf(wi, wo); }
vec3 sample_body(vec3 wo, vec3 u) { return sample_lobe(wo, u); }
float pdf_body(vec3 wo, vec3 wi) { return pdf_lobe(wo, wi); }
#endif

const vec3 LUMA = vec3(0.2126, 0.7152, 0.0722);  // Rec. 709 luminance weights

// A sample's contribution, scaled down to luminance u_clamp at most when the clamp is on.
vec3 clamp_contribution(vec3 c) {
    float y = dot(c, LUMA);
    return u_clamp > 0.0 && y > u_clamp ? c * (u_clamp / y) : c;
}

#ifdef NB_SPLIT_COAT
// The coat's balance-heuristic estimator over every environment direction the
// pass looks up (environment and resampling candidates) and its own samples:
// per-pass sample counts per strategy (environment, body lobe, coat) and the coat.
int coat_n;
vec3 coat_counts;
vec2 coat_pass;

// The balance heuristic's denominator for a coat direction l: every strategy's
// sample count times its pdf (environment ``pe``, body lobe ``pb``, coat).
float coat_mis_pdf(vec3 wo, vec3 l, float pe, float pb) {
    return coat_counts.x * pe + coat_counts.y * pb + float(coat_n) * coat_pdf(wo, l, coat_pass);
}

// One looked-up direction's share of the coat integral (clamped like any sample).
vec3 coat_candidate(vec3 wo, vec3 l, vec3 radiance, float pe, float pb) {
    if (coat_pass.y <= 1.0 + 1e-4) return vec3(0.0);
    float pc = coat_mis_pdf(wo, l, pe, pb);
    return pc > 0.0 ? clamp_contribution(coat_eval(l, wo, coat_pass) * l.z * radiance / pc) : vec3(0.0);
}
#endif

#ifdef NB_SPLIT_COAT
// The coat's own samples added to ``color``: its visible normals, ``coat_n`` per pass (no decoder),
// balance heuristic with every strategy's sample counts (``coat_mis_pdf``); each added in turn, as
// the sums of shade_lit and shade_lit_every must be the same.
vec3 coat_own_samples(mat3 tbn, vec3 wo, uvec2 px, uint pass_index, vec2 coat, vec3 color) {
    int n = (u_terms & TERM_LOBE_COAT) != 0 ? coat_n : 0;
    for (int j = 0; j < n; ++j) {
        vec3 l = coat_sample(wo, rand3(px, pass_index * uint(coat_n) + uint(j), STREAM_COAT, u_seed).xy, coat);
        if (l.z <= 0.0) continue;
        vec3 lw = tbn * l;
        float pc = coat_mis_pdf(wo, l, pdf_env(lw), pdf_body(wo, l));
        if (pc > 0.0)
            color += clamp_contribution(coat_eval(l, wo, coat) * l.z * env_radiance(lw) * u_env_intensity / pc);
    }
    return color;
}
#endif

// Resampled importance sampling of the body (Talbot et al. 2005): ``m`` cheap
// candidates, half from the environment's CDF and half from the body's lobe,
// weighted by a target without the decoder; one is kept with probability
// proportional to its weight, and the decoder runs at it alone. Returns the
// kept direction (local; z <= 0: none) and in ``weight`` the radiance over its
// effective pdf, L(l) x (sum of weights) / (m x target(l)): unbiased for any
// target that is positive wherever the body and the lighting are. Every
// candidate also feeds the coat's balance-heuristic estimator, added to ``coat_sum``.
// The target: where the draw has the body's baked table (u_ris_table, a uniform
// latent), lum(T(l) L(l)) cos(l), the table T the body to its interpolation
// error (one fetch), so the kept sample's weight is nearly constant; else
// lighting times the lobe sampler's pdf, lum(L(l)) x (pdf_body(l) + cos(l) / (4 pi)).
#ifdef NB_BODY_GUIDE
uniform int u_ris_table;  // 1: the resampling target from the body's baked table
#endif
float ris_target(vec3 wo, vec3 l, vec3 radiance) {
#ifdef NB_BODY_GUIDE
    if (u_ris_table != 0) return dot(NB_BODY_GUIDE(l, wo) * radiance, LUMA) * l.z;
#endif
    return dot(radiance, LUMA) * (pdf_body(wo, l) + max(l.z, 0.0) * (0.25 / PI));
}

// ``n_lobe`` > 0: that many candidates from the lobe, the rest from the environment,
// each strategy a contiguous run of its Sobol sequence (0: alternating halves).
vec3 ris_body_sample(mat3 tbn, vec3 wo, uvec2 px, uint draw, int m, int n_lobe, inout vec3 coat_sum,
                     out vec3 weight) {
    float u = rand3(px, draw, STREAM_PICK, u_seed).x;
    float wsum = 0.0, target = 0.0;
    vec3 kept = vec3(0.0, 0.0, -1.0), kept_radiance = vec3(0.0);
    int half_m = m / 2, n_env = m - n_lobe;
    for (int i = 0; i < m; ++i) {
        bool env = n_lobe > 0 ? i < n_env : i % 2 == 0;
        uint index = n_lobe == 0 ? draw * uint(half_m) + uint(i / 2)
                   : env ? draw * uint(n_env) + uint(i) : draw * uint(n_lobe) + uint(i - n_env);
        vec3 l;
        float unused;
        if (env) l = transpose(tbn) * sample_env(rand3(px, index, STREAM_ENV, u_seed).xy, unused);
        else l = sample_body(wo, rand3(px, index, STREAM_LOBE, u_seed));
        if (l.z <= 0.0) continue;
        vec3 lw = tbn * l;
        float pe = pdf_env(lw), pb = pdf_body(wo, l);
        // The candidates' mixture (balance heuristic over the two strategies' counts).
        float q = n_lobe > 0 ? (float(n_env) * pe + float(n_lobe) * pb) / float(m) : 0.5 * (pe + pb);
        if (q <= 0.0) continue;
        vec3 radiance = env_radiance(lw) * u_env_intensity;
#ifdef NB_SPLIT_COAT
        coat_sum += coat_candidate(wo, l, radiance, pe, pb);
#endif
        float g = ris_target(wo, l, radiance);
        float w = g / q;
        if (w <= 0.0) continue;
        wsum += w;
        // Streaming selection with one uniform: keep candidate i with probability w / wsum,
        // then rescale u to stay uniform on what is left.
        float t = w / wsum;
        if (u < t) {
            kept = l; kept_radiance = radiance; target = g;
            u = u / t;
        } else {
            u = (u - t) / (1.0 - t);
        }
    }
    weight = target > 0.0 ? kept_radiance * (wsum / (float(m) * target)) : vec3(0.0);
    return kept;
}

// The body where it is cheap (the baked table): no resampling, ``m`` directions
// per draw -- ``n_lobe`` from the body's lobe, the rest from the environment's
// CDF, each strategy a contiguous run of its Sobol sequence -- and the body at
// every one, balance heuristic over the two strategies (the mixture's pdf).
// Returns the draw's estimate of the body's environment light; every direction
// also feeds the coat's estimator (``coat_sum``).
vec3 every_body_samples(mat3 tbn, vec3 wo, uvec2 px, uint draw, int m, int n_lobe, inout vec3 coat_sum) {
    int n_env = m - n_lobe;
    vec3 sum = vec3(0.0);
    for (int i = 0; i < m; ++i) {
        bool env = i < n_env;
        vec3 l;
        float unused;
        if (env) l = transpose(tbn) * sample_env(rand3(px, draw * uint(n_env) + uint(i), STREAM_ENV, u_seed).xy, unused);
        else l = sample_body(wo, rand3(px, draw * uint(n_lobe) + uint(i - n_env), STREAM_LOBE, u_seed));
        if (l.z <= 0.0) continue;
        vec3 lw = tbn * l;
        float pe = pdf_env(lw), pb = pdf_body(wo, l);
        float q = float(n_env) * pe + float(n_lobe) * pb;  // m x the mixture's pdf
        if (q <= 0.0) continue;
        vec3 radiance = env_radiance(lw) * u_env_intensity;
#ifdef NB_SPLIT_COAT
        coat_sum += coat_candidate(wo, l, radiance, pe, pb);
#endif
        sum += clamp_contribution(body_brdf(l, wo) * (l.z / q) * radiance * float(m)) / float(m);
    }
    return sum;
}

// ``tbn``: the shading frame (columns tangent, bitangent, normal; world);
// ``view``: unit vector to the eye; ``world``: the surface point.
vec3 shade_lit(mat3 tbn, vec3 view, vec3 world, uvec2 px, uint pass_index) {
    mat3 to_local = transpose(tbn);
    vec3 wo = to_local * view;
    vec3 color = vec3(0.0);
    bool ris = u_ris_samples > 0 && u_ris_candidates > 1;
    int m = ris ? u_ris_candidates - u_ris_candidates % 2 : 0;
    bool every = ris && u_body_every > 0;
    // Candidates per resampled sample or per every-candidate draw from the body's lobe (0: half, alternating).
    int n_lobe = every ? min(u_body_every, u_ris_candidates - 1) : ris && u_ris_lobe > 0 ? min(u_ris_lobe, m - 1) : 0;
    if (every) m = u_ris_candidates;
    int count = u_env_on == 0 ? 1 : ris ? 1 + u_ris_samples : u_one_sample != 0 ? 2 : u_strategies;
    bool cosine = u_strategies > 3 || u_one_sample != 0;
#ifdef NB_SPLIT_COAT
    vec2 coat = coat_code();
    bool coated = u_env_on != 0 && coat_params(coat).y > 1.0 + 1e-4;
    coat_n = coated ? max(u_coat_samples, 0) : 0;
    // The coat estimator's sample counts per strategy (environment, body lobe, coat).
    coat_counts = every ? vec3(float((m - n_lobe) * u_ris_samples), float(n_lobe * u_ris_samples), float(coat_n))
                : ris && n_lobe > 0 ? vec3(float((m - n_lobe) * u_ris_samples), float(n_lobe * u_ris_samples),
                                           float(coat_n))
                : ris ? vec3(float(m / 2 * u_ris_samples), float(m / 2 * u_ris_samples), float(coat_n))
                      : vec3(u_one_sample != 0 ? 1.0 / 3.0 : 1.0, 0.0, float(coat_n));
    coat_pass = coated ? coat : vec2(0.05, 1.0);
#endif
    vec3 coat_sum = vec3(0.0);
    // One-sample MIS: the strategy of the single environment sample, chosen uniformly.
    float pick = u_one_sample != 0 ? rand3(px, pass_index, STREAM_PICK, u_seed).x * 3.0 : 0.0;
    for (int k = u_point_on != 0 ? -1 : 0; k < count; ++k) {
        vec3 l;
        float unused;
        vec3 to_point = u_point_pos - world;
        int s = ris && k > 0 ? 4 : k == 1 && u_one_sample != 0 ? 1 + min(int(pick), 2) : k;
        vec3 ris_weight = vec3(0.0);
        if (s == -1) l = to_local * normalize(to_point);
        else if (s == 0) l = to_local * normalize(u_light_dir);
        else if (s == 1) l = to_local * sample_env(rand3(px, pass_index, STREAM_ENV, u_seed).xy, unused);
        else if (s == 2) l = sample_body(wo, rand3(px, pass_index, STREAM_LOBE, u_seed));
        else if (s == 3) l = sample_cosine(rand3(px, pass_index, STREAM_COS, u_seed).xy, unused);
        else if (every) {  // the body's directions, evaluated and summed
            vec3 e = every_body_samples(tbn, wo, px, pass_index * uint(u_ris_samples) + uint(k - 1), m, n_lobe,
                                        coat_sum);
            if ((u_terms & TERM_ENV_BODY) != 0) color += e / float(u_ris_samples);
            continue;
        }
        else l = ris_body_sample(tbn, wo, px, pass_index * uint(u_ris_samples) + uint(k - 1), m, n_lobe, coat_sum,
                                 ris_weight);
        if (l.z <= 0.0) continue;
        int term = s <= 0 ? TERM_LIGHT : s == 1 || s == 4 ? TERM_ENV_BODY : s == 2 ? TERM_LOBE_BODY : TERM_COS_BODY;
        vec3 radiance;
        float p = 1.0;  // the balance heuristic's denominator (1: a light, or the resampled weight)
        vec3 lw = tbn * l;
        if (k == -1) {
            radiance = u_point_intensity / max(dot(to_point, to_point), 1e-8);
        } else if (k == 0) {
            radiance = u_light_radiance;
        } else if (s == 4) {
            radiance = ris_weight / float(u_ris_samples);  // each resampled sample estimates the whole body
        } else {
            float pe = pdf_env(lw);
            p = pe + pdf_body(wo, l) + (cosine ? pdf_cosine(l) : 0.0);
            if (u_one_sample != 0) p *= 1.0 / 3.0;  // the mixture's pdf
            radiance = env_radiance(lw) * u_env_intensity;
#ifdef NB_SPLIT_COAT
            if (s == 1) coat_sum += coat_candidate(wo, l, radiance, pe, 0.0);
#endif
        }
        bool keep = (u_terms & term) != 0;
        vec3 f = keep && p > 0.0 ? body_brdf(l, wo) : vec3(0.0);
#ifdef NB_SPLIT_COAT
        if (s <= 0 && keep) f += vec3(coat_eval(l, wo, coat));  // the lights see the whole BRDF
#endif
        if (p > 0.0) color += s <= 0 ? f * l.z * radiance : clamp_contribution(f * l.z * radiance / p);
    }
#ifdef NB_SPLIT_COAT
    color = coat_own_samples(tbn, wo, px, pass_index, coat, color);
    if ((u_terms & TERM_ENV_COAT) != 0) color += coat_sum;
#endif
    return color;
}

#if defined(NB_EVERY_CANDIDATE) || defined(NB_ENV_TABLE)
// The lights added to ``color`` as shade_lit adds them (the point light, then the directional one;
// the whole BRDF, the coat included where it is split), for the programs of their own below.
vec3 light_term(vec3 l, vec3 wo, vec3 radiance) {
    vec3 f = body_brdf(l, wo);
#ifdef NB_SPLIT_COAT
    f += vec3(coat_eval(l, wo, coat_code()));
#endif
    return f * l.z * radiance;
}

// A loop over the lights that are on, not a branch per light: llvmpipe runs a branch's code under
// a mask whether or not it is taken, and a loop's trip count (uniform here) skips what is off.
vec3 add_lights(mat3 to_local, vec3 wo, vec3 world, vec3 color) {
    for (int i = u_point_on != 0 ? 0 : 1; i < 2; ++i) {
        vec3 to_point = u_point_pos - world;
        vec3 l = to_local * normalize(i == 0 ? to_point : u_light_dir);
        vec3 radiance = i == 0 ? u_point_intensity / max(dot(to_point, to_point), 1e-8) : u_light_radiance;
        if (l.z > 0.0) color += light_term(l, wo, radiance);
    }
    return color;
}
#endif

#ifdef NB_ENV_TABLE
// The still view where the body's environment light is pre-integrated over the
// object's normals (env_table.glsl, viewer/gpu/env_prefilter.py): the lights (the
// whole BRDF), the body's environment light from the map at the shading normal
// (one fetch), and the clear coat's environment light from u_coat_samples of its own
// visible normals (and a quarter as many of the environment's CDF under a sun, balance
// heuristic). A program of its own: llvmpipe runs the straight-line code of every branch
// under a mask, so the sampling strategies this pass does not use are compiled out, not
// skipped (so the coat's balance heuristic here is not shade_lit's coat_mis_pdf, which
// would evaluate the body's pdf and the environment's for every sample).
//@INCLUDE env_table.glsl
uniform sampler2D u_env_table;

#ifdef NB_SPLIT_COAT
// One sampled direction l (local; lw in world) of the coat's environment light, weighted by the balance
// heuristic over its n visible-normal and ne environment-CDF samples.
vec3 coat_env_sample(vec3 wo, vec3 l, vec3 lw, vec2 coat, int n, int ne) {
    if (l.z <= 0.0) return vec3(0.0);
    float pe = 0.0;
    for (int t = 0; t < min(ne, 1); ++t) pe = pdf_env(lw);  // a loop, not a branch: skipped where ne is 0
    float p = float(n) * coat_pdf(wo, l, coat) + float(ne) * pe;
    return p > 0.0 ? clamp_contribution(coat_eval(l, wo, coat) * l.z * env_radiance(lw) * u_env_intensity / p)
                   : vec3(0.0);
}
#endif

vec3 shade_lit_mapped(mat3 tbn, vec3 view, vec3 world, uvec2 px, uint pass_index) {
    mat3 to_local = transpose(tbn);
    vec3 wo = to_local * view;
    vec3 color = vec3(0.0);
    if ((u_terms & TERM_LIGHT) != 0) color = add_lights(to_local, wo, world, color);
    if (u_env_on == 0) return color;
    if ((u_terms & TERM_ENV_BODY) != 0) color += textureLod(u_env_table, env_table_uv(tbn[2]), 0.0).rgb;
#ifdef NB_SPLIT_COAT
    // The coat: its visible-normal samples and, under a peaked environment, a quarter as many of the
    // environment's CDF, balance heuristic. Its own samples alone left a small bright source (the sky's
    // sun) to the few that hit it: fireflies the 16-pass cap no longer averaged away (record 121).
    vec2 coat = coat_code();
    bool coated = coat_params(coat).y > 1.0 + 1e-4;
    int n = coated && (u_terms & TERM_LOBE_COAT) != 0 ? max(u_coat_samples, 0) : 0;
    // a peaked environment only (a sun: EnvironmentMap.peaked); 0 in the edits' quick frames (1 coat sample)
    int ne = coated && u_env_peaked != 0 && (u_terms & TERM_ENV_COAT) != 0 ? max(u_coat_samples, 0) / 4 : 0;
    // two loops, not a branch per sample: llvmpipe runs both sides of a branch under a mask
    for (int j = 0; j < n; ++j) {
        vec3 l = coat_sample(wo, rand3(px, pass_index * uint(n) + uint(j), STREAM_COAT, u_seed).xy, coat);
        color += coat_env_sample(wo, l, tbn * l, coat, n, ne);
    }
    for (int j = 0; j < ne; ++j) {
        float unused;
        vec3 lw = sample_env(rand3(px, pass_index * uint(ne) + uint(j), STREAM_ENV, u_seed).xy, unused);
        color += coat_env_sample(wo, to_local * lw, lw, coat, n, ne);
    }
#endif
    return color;
}
#endif

#ifdef NB_EVERY_CANDIDATE
// shade_lit with the body evaluated at every candidate (u_body_every > 0, u_ris_samples
// draws; the baked table's estimator, LitSampling.every_candidate) and nothing else: the
// same estimator, random numbers and order of sums, in a program of its own, since
// llvmpipe runs the straight-line code of every branch of shade_lit under a mask (the
// strategies this estimator does not use cost about half its pass).
vec3 shade_lit_every(mat3 tbn, vec3 view, vec3 world, uvec2 px, uint pass_index) {
    mat3 to_local = transpose(tbn);
    vec3 wo = to_local * view;
    vec3 color = vec3(0.0);
    int m = u_ris_candidates;
    int n_lobe = min(u_body_every, u_ris_candidates - 1);
#ifdef NB_SPLIT_COAT
    vec2 coat = coat_code();
    bool coated = u_env_on != 0 && coat_params(coat).y > 1.0 + 1e-4;
    coat_n = coated ? max(u_coat_samples, 0) : 0;
    coat_counts = vec3(float((m - n_lobe) * u_ris_samples), float(n_lobe * u_ris_samples), float(coat_n));
    coat_pass = coated ? coat : vec2(0.05, 1.0);
#endif
    vec3 coat_sum = vec3(0.0);
    if ((u_terms & TERM_LIGHT) != 0) color = add_lights(to_local, wo, world, color);
    if (u_env_on == 0) return color;
    for (int k = 1; k <= u_ris_samples; ++k) {
        vec3 e = every_body_samples(tbn, wo, px, pass_index * uint(u_ris_samples) + uint(k - 1), m, n_lobe, coat_sum);
        if ((u_terms & TERM_ENV_BODY) != 0) color += e / float(u_ris_samples);
    }
#ifdef NB_SPLIT_COAT
    color = coat_own_samples(tbn, wo, px, pass_index, coat, color);
    if ((u_terms & TERM_ENV_COAT) != 0) color += coat_sum;
#endif
    return color;
}
#endif
