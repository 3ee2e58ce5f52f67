#pragma once
// Plain-English captions of a synth frame, built from its structured labels (scene.h: Scene::labels) with
// seeded variation in wording and clause order, e.g. "rainy night, red light ahead, slowing behind a bus".
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace gaia::synth {

// Caption for one frame; `key` seeds the wording (same key and labels -> same caption).
std::string make_caption(const nlohmann::json& labels, uint64_t key);

// The conditions phrase alone ("rainy night", "sunny day", ...), worded as make_caption words it: captions of real
// footage, whose manifest gives weather and time of day, share the procedural captions' words.
std::string conditions_caption(const std::string& weather, const std::string& time_of_day, uint64_t key);

// Words of which at least one appears in every caption of that weather / time of day (lower case), so
// probes and tests can check captions against labels.
const std::vector<std::string>& weather_words(const std::string& weather);
const std::vector<std::string>& time_words(const std::string& time_of_day);

}  // namespace gaia::synth
