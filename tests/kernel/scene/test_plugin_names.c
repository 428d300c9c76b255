/* The unknown-plugin-type error (server/kernel/scene/plugin_names.c,
 * issue 25 item 3): it names the closest known type and lists the known
 * plugins of the class the document asked for: from the XML tag, from the
 * JSON slot (`bsdf`, `interior`), else from the closest name, else all of
 * them; the closest name is sought within that class first. Each case
 * loads a scene and checks the message. */
#include <stdio.h>
#include <string.h>

#include "../../support/test.h"
#include "kernel/scene/scene.h"

RSW_TEST_DEFINE_GLOBALS

static void load_msg(const char *text, char *out, size_t n) {
  scene_load_opts o = {.size = sizeof o, .variant = "mono"};
  rsw_err err = {0};
  scene *s = NULL;
  rsw_status st = scene_load_memory(text, strlen(text), "doc", text[0] == '<', &o, &s, &err);
  CHECK(st == RSW_ERR_UNKNOWN_PLUGIN, "status %d for %s", (int)st, text);
  if (s) scene_free(s);
  rsw_err_format(&err, out, n);
}

static void expect_in(const char *msg, const char *want, bool present) {
  CHECK((strstr(msg, want) != NULL) == present, "'%s' %s in: %s", want, present ? "not" : "wrongly", msg);
}

static void test_json_slot(void) {
  char m[1400];
  load_msg("{\"type\": \"scene\", \"p\": {\"type\": \"rectangle\", \"bsdf\": {\"type\": \"rtl\"}}}", m,
           sizeof m);
  expect_in(m, "unknown plugin type 'rtl' (did you mean 'rtls'?)", true);
  expect_in(m, "known bsdf plugins: diffuse, ", true);
  expect_in(m, "maignan", true);
  expect_in(m, "hdrfilm", false); /* not a BSDF */
  expect_in(m, "#/p/bsdf", true);
  /* A medium slot lists media; the closest name comes from them. */
  load_msg("{\"type\": \"scene\", \"c\": {\"type\": \"cube\", \"interior\": {\"type\": \"homogenous\"}}}", m,
           sizeof m);
  expect_in(m, "did you mean 'homogeneous'?", true);
  expect_in(m, "known medium plugins: ", true);
  expect_in(m, "piecewise", true);
  expect_in(m, "diffuse", false);
}

static void test_xml_tag(void) {
  char m[1400];
  load_msg("<scene version=\"3.0.0\"><shape type=\"rectangle\"><bsdf type=\"difuse\"/></shape></scene>", m,
           sizeof m);
  expect_in(m, "did you mean 'diffuse'?", true);
  expect_in(m, "known bsdf plugins: ", true);
  /* Mitsuba's mitchell filter (not built here): nothing close, the rfilters are listed. */
  load_msg("<scene version=\"3.0.0\"><sensor type=\"perspective\"><film type=\"hdrfilm\">"
           "<rfilter type=\"mitchell\"/></film></sensor></scene>",
           m, sizeof m);
  expect_in(m, "unknown plugin type 'mitchell'; known rfilter plugins: box, gaussian, tent, lanczos", true);
  expect_in(m, "did you mean", false);
}

static void test_no_hint(void) {
  char m[1400];
  /* A top-level child: the class comes from the closest name. */
  load_msg("{\"type\": \"scene\", \"s\": {\"type\": \"spere\"}}", m, sizeof m);
  expect_in(m, "did you mean 'sphere'?", true);
  expect_in(m, "known shape plugins: ", true);
  /* Nothing close: every plugin a document may name, `periodic`
   * included, the root `scene` not. */
  load_msg("{\"type\": \"scene\", \"s\": {\"type\": \"zzzzzzzz\"}}", m, sizeof m);
  expect_in(m, "; known plugins: rectangle, ", true);
  expect_in(m, "periodic", true);
  expect_in(m, "scene,", false);
}

int main(void) {
  RSW_TEST_RUN(test_json_slot);
  RSW_TEST_RUN(test_xml_tag);
  RSW_TEST_RUN(test_no_hint);
  RSW_TEST_END("test_plugin_names");
}
