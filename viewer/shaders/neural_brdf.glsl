// The BRDF of a view as the neural decoder at the material's latents
// (uniform u_nb_share). Until the learned proxy pdf lands, the lit view
// importance-samples a GGX lobe of the roughness the CPU derives from the
// material's top layer (u_lobe_roughness), MIS with cosine sampling.
//@INCLUDE neural_decoder.glsl
uniform float u_lobe_roughness;
vec3 brdf(vec3 wi, vec3 wo) { return nb_decode(wi, wo); }
float lobe_roughness() { return u_lobe_roughness; }
