#include "bsdf_test.h"

#include "../../server/kernel/textures/texture.h"

#include <string.h>

vec3 tb_dir_deg(double theta_deg, double phi_deg) {
  double t = theta_deg * RSW_PI / 180.0, p = phi_deg * RSW_PI / 180.0;
  return v3(sin(t) * cos(p), sin(t) * sin(p), cos(t));
}

surface_interaction tb_si_with(vec3 wi) {
  surface_interaction si;
  memset(&si, 0, sizeof si);
  si.sh = frame_from_normal(v3(0, 0, 1));
  si.wi = wi;
  return si;
}

void tb_free_bsdf(bsdf *b) {
  if (b) b->base.plugin->destroy(&b->base);
}

void tb_free_tex(texture *t) {
  if (t) t->base.plugin->destroy(&t->base);
}

bool chi2_bsdf_sample(void *user, const double *u, vec3 *out, double *weight) {
  chi2_bsdf *c = user;
  bsdf_sample bs;
  color w = c->b->ops->sample(c->b, &c->si, u[0], v2(u[1], u[2]), &bs);
  if (!(bs.pdf > 0.0) || col_is_black(w)) {
    *weight = 0.0;
    return false;
  }
  *out = bs.wo;
  *weight = 1.0;
  return true;
}

double chi2_bsdf_pdf(void *user, vec3 wo) {
  chi2_bsdf *c = user;
  return c->b->ops->pdf(c->b, &c->si, wo);
}

rough_case rough_make(mf_type type, double au, double av, bool visible, double eta, double k) {
  rough_case r;
  r.au = uniform_texture_const(au, "alpha_u");
  r.av = au == av ? NULL : uniform_texture_const(av, "alpha_v");
  r.eta = uniform_texture_const(eta, "eta");
  r.k = uniform_texture_const(k, "k");
  r.b = roughconductor_new(type, r.au, r.av, visible, r.eta, r.k, NULL, NULL, NULL);
  return r;
}

void rough_free(rough_case *r) {
  tb_free_bsdf(r->b);
  tb_free_tex(r->au);
  tb_free_tex(r->av);
  tb_free_tex(r->eta);
  tb_free_tex(r->k);
}

const char *mf_type_name(mf_type t) {
  return t == MF_GGX ? "ggx" : "beckmann";
}
