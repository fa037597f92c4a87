// The BRDF of a view as the neural decoder at the material's latents
// (uniform u_nb_share). The lit view importance-samples the material's learned
// proxy pdf (u_proxy_sigma, u_proxy_w, computed once per material on the CPU),
// MIS with cosine sampling.
//@INCLUDE neural_decoder.glsl
//@INCLUDE sampling.glsl
uniform float u_proxy_sigma;
uniform float u_proxy_w;
vec3 brdf(vec3 wi, vec3 wo) { return nb_decode(wi, wo); }
vec3 sample_lobe(vec3 wo, vec3 u) { return sample_proxy(wo, u, u_proxy_sigma, u_proxy_w); }
float pdf_lobe(vec3 wo, vec3 wi) { return pdf_proxy(wo, wi, u_proxy_sigma, u_proxy_w); }
