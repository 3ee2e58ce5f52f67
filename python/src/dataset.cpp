// gaia.Dataset: an episode dataset (gaia ingest / gaia synth) or a token dataset (gaia tokenize), read-only.
#include <fstream>
#include <optional>

#include <nlohmann/json.hpp>
#include <pybind11/stl.h>

#include "arrays.h"
#include "gaia/core/error.h"
#include "gaia/data/episode.h"
#include "gaia/world/token_dataset.h"

namespace gaia::python {

namespace {

struct DatasetHandle {
  std::string path;
  std::unique_ptr<data::Dataset> episodes;    // one of the two
  std::unique_ptr<world::TokenDataset> tokens;
  const std::vector<std::string>& ids() const { return episodes ? episodes->ids() : tokens->ids(); }
};

struct EpisodeHandle {
  std::shared_ptr<DatasetHandle> ds;
  size_t index = 0;
  std::shared_ptr<data::Episode> ep;  // episode datasets
};

py::object from_json(const nlohmann::json& j) { return py::module_::import("json").attr("loads")(j.dump()); }

torch::Tensor floats(const std::vector<float>& v) {
  return torch::from_blob(const_cast<float*>(v.data()), {int64_t(v.size())}, torch::kFloat).clone();
}

size_t index_of(const DatasetHandle& d, const py::object& key) {
  if (py::isinstance<py::str>(key)) {
    const auto id = key.cast<std::string>();
    const auto& ids = d.ids();
    for (size_t i = 0; i < ids.size(); ++i)
      if (ids[i] == id) return i;
    throw py::key_error(fmt::format("{}: no episode '{}'", d.path, id));
  }
  if (!py::isinstance<py::int_>(key)) throw py::type_error("an episode index (int) or id (str) expected");
  auto i = key.cast<int64_t>();
  const auto n = int64_t(d.ids().size());
  if (i < 0) i += n;
  if (i < 0 || i >= n) throw py::index_error(fmt::format("{}: episode {} of {}", d.path, key.cast<int64_t>(), n));
  return size_t(i);
}

}  // namespace

void bind_dataset(py::module_& m) {
  py::class_<EpisodeHandle, std::shared_ptr<EpisodeHandle>>(m, "Episode", R"(One episode of a gaia.Dataset.

Episode datasets: frames (RGB uint8) at the native rate with speed, curvature, times and captions a frame.
Token datasets: tokens (int16 [T, h, w]) at the world-model rate with speed, curvature and captions a step.)")
      .def_property_readonly("id", [](const EpisodeHandle& e) { return e.ds->ids()[e.index]; })
      .def_property_readonly("metadata", [](const EpisodeHandle& e) {
        return from_json(e.ep ? e.ep->meta().to_json() : e.ds->tokens->meta(e.index).to_json());
      }, "episode.json as a dict: fps, weather, time of day, place, source, signals_source, ...")
      .def("__len__", [](const EpisodeHandle& e) {
        return e.ep ? e.ep->size() : e.ds->tokens->steps(e.index);
      })
      .def_property_readonly("speed", [](const EpisodeHandle& e) {
        if (e.ep) return array_of(floats(e.ep->speeds()));
        return array_of(floats(e.ds->tokens->actions(e.index)).view({-1, 2}).select(1, 0).contiguous());
      }, "float32 [N] m/s, NaN = missing")
      .def_property_readonly("curvature", [](const EpisodeHandle& e) {
        if (e.ep) return array_of(floats(e.ep->curvatures()));
        return array_of(floats(e.ds->tokens->actions(e.index)).view({-1, 2}).select(1, 1).contiguous());
      }, "float32 [N] 1/m (+ = left), NaN = missing")
      .def_property_readonly("actions", [](const EpisodeHandle& e) {
        if (e.ep) return array_of(torch::stack({floats(e.ep->speeds()), floats(e.ep->curvatures())}, 1));
        return array_of(floats(e.ds->tokens->actions(e.index)).view({-1, 2}));
      }, "float32 [N, 2]: speed and curvature a row, as WorldModel.rollout and Sim.create take them")
      .def_property_readonly("time_s", [](const EpisodeHandle& e) -> py::object {
        if (!e.ep) return py::none();
        const auto& t = e.ep->times();
        return array_of(torch::from_blob(const_cast<double*>(t.data()), {int64_t(t.size())}, torch::kDouble).clone());
      }, "float64 [N] timestamps (episode datasets)")
      .def_property_readonly("captions", [](const EpisodeHandle& e) {
        std::vector<std::string> out;
        if (e.ep) {
          for (int64_t i = 0; i < e.ep->size(); ++i) out.push_back(e.ep->caption(i));
        } else {
          py::gil_scoped_release free;
          out = e.ds->tokens->episode(e.index)->captions;
        }
        return out;
      })
      .def_property_readonly("tokens", [](const EpisodeHandle& e) -> py::object {
        if (e.ep) throw py::value_error(fmt::format("{}: an episode dataset holds frames, not tokens (frames())", e.ds->path));
        auto& ds = *e.ds->tokens;
        std::shared_ptr<const world::TokenEpisode> t;
        {
          py::gil_scoped_release free;
          t = ds.episode(e.index);
        }
        auto z = torch::from_blob(const_cast<int32_t*>(t->tokens.data()), {ds.steps(e.index), ds.grid_h(), ds.grid_w()},
                                  torch::kInt);
        return array_of(z.to(torch::kShort));
      }, "int16 [T, h, w] (token datasets)")
      .def("frames", [](const EpisodeHandle& e, int64_t start, std::optional<int64_t> stop) {
        if (!e.ep) throw py::value_error(fmt::format("{}: a token dataset holds tokens, not frames (.tokens)", e.ds->path));
        const int64_t N = e.ep->size(), end = stop ? std::min(*stop, N) : N;
        if (start < 0 || start > end)
          throw py::value_error(fmt::format("start: [0, {}] expected, got {}", end, start));
        const auto& meta = e.ep->meta();
        auto out = torch::empty({end - start, meta.height, meta.width, 3}, torch::kUInt8);
        {
          py::gil_scoped_release free;
          for (int64_t i = start; i < end; ++i) {
            cv::Mat f = e.ep->frame_bgr(i);
            auto t = torch::from_blob(f.data, {f.rows, f.cols, 3}, torch::kUInt8);
            out[i - start].copy_(t.flip({2}));
          }
        }
        return array_of(out);
      }, py::arg("start") = 0, py::arg("stop") = py::none(), "RGB uint8 frames [stop - start, H, W, 3]");

  py::class_<DatasetHandle, std::shared_ptr<DatasetHandle>>(m, "Dataset", R"(A dataset opened read-only.

Dataset(path): an episode dataset (`gaia ingest`, `gaia synth`) or a token dataset (`gaia tokenize`, or token
files of another tokenizer). len(ds), ds.ids, ds[i] or ds["id"] -> gaia.Episode.)")
      .def(py::init([](const std::string& path) {
        require_path(path, "dataset");
        auto d = std::make_shared<DatasetHandle>();
        d->path = path;
        std::string format;
        const fs::path meta = fs::path(path) / "dataset.json";
        if (fs::exists(meta)) {
          std::ifstream f(meta);
          auto j = nlohmann::json::parse(f, nullptr, false);
          if (j.is_discarded() || !j.is_object()) throw py::value_error(meta.string() + ": not a JSON object");
          format = j.value("format", "");
        }
        if (format == "gaia-episodes") d->episodes = std::make_unique<data::Dataset>(path);
        else d->tokens = std::make_unique<world::TokenDataset>(path);
        return d;
      }), py::arg("path"))
      .def_property_readonly("kind", [](const DatasetHandle& d) { return d.episodes ? "episodes" : "tokens"; })
      .def_property_readonly("path", [](const DatasetHandle& d) { return d.path; })
      .def_property_readonly("ids", [](const DatasetHandle& d) { return d.ids(); })
      .def_property_readonly("grid", [](const DatasetHandle& d) -> py::object {
        if (!d.tokens) return py::none();
        return py::make_tuple(d.tokens->grid_h(), d.tokens->grid_w());
      }, "(h, w) of a token dataset")
      .def_property_readonly("rate_hz", [](const DatasetHandle& d) -> py::object {
        if (!d.tokens) return py::none();
        return py::float_(d.tokens->rate_hz());
      })
      .def("__len__", [](const DatasetHandle& d) { return d.ids().size(); })
      .def("__getitem__", [](std::shared_ptr<DatasetHandle> d, const py::object& key) {
        auto e = std::make_shared<EpisodeHandle>();
        e->ds = d;
        e->index = index_of(*d, key);
        if (d->episodes) e->ep = std::make_shared<data::Episode>(d->episodes->episode(e->index));
        return e;
      }, py::arg("key"))
      .def("__iter__", [](std::shared_ptr<DatasetHandle> d) {
        py::list all;
        auto self = py::cast(d);
        for (size_t i = 0; i < d->ids().size(); ++i) all.append(self.attr("__getitem__")(i));
        return py::iter(all);
      });
}

}  // namespace gaia::python
