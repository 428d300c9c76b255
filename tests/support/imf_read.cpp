// Second EXR reader for the tests (see imf_read.h): Imf::InputFile.
#include "imf_read.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfStringAttribute.h>

int imf_read_float(const char *path, imf_image *out, char *msg, size_t msg_len) {
  float *data = nullptr;
  try {
    Imf::InputFile file(path);
    const Imath::Box2i dw = file.header().dataWindow();
    const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    const Imf::ChannelList &chl = file.header().channels();
    int nc = 0;
    for (Imf::ChannelList::ConstIterator it = chl.begin(); it != chl.end(); ++it) nc++;
    if (nc < 1 || nc > IMF_READ_MAX_CHANNELS) {
      std::snprintf(msg, msg_len, "%s: %d channels", path, nc);
      return -1;
    }
    data = static_cast<float *>(std::calloc((size_t)w * (size_t)h * (size_t)nc, sizeof(float)));
    if (!data) {
      std::snprintf(msg, msg_len, "%s: out of memory", path);
      return -1;
    }
    Imf::FrameBuffer fb;
    imf_image img;
    std::memset(&img, 0, sizeof img);
    int c = 0;
    const size_t xs = sizeof(float) * (size_t)nc, ys = xs * (size_t)w;
    for (Imf::ChannelList::ConstIterator it = chl.begin(); it != chl.end(); ++it, ++c) {
      std::snprintf(img.names[c], sizeof img.names[c], "%.63s", it.name());
      fb.insert(it.name(), Imf::Slice::Make(Imf::FLOAT, data + c, dw, xs, ys));
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    img.width = w;
    img.height = h;
    img.n_channels = nc;
    img.data = data;
    *out = img;
    return 0;
  } catch (const std::exception &e) {
    std::free(data);
    std::snprintf(msg, msg_len, "%s", e.what());
    return -1;
  }
}

char *imf_read_string_attr(const char *path, const char *key) {
  try {
    Imf::InputFile file(path);
    const Imf::StringAttribute *a = file.header().findTypedAttribute<Imf::StringAttribute>(key);
    if (!a) return nullptr;
    const std::string &v = a->value();
    char *s = static_cast<char *>(std::malloc(v.size() + 1));
    if (s) std::memcpy(s, v.c_str(), v.size() + 1);
    return s;
  } catch (const std::exception &) {
    return nullptr;
  }
}
