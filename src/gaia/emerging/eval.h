#pragma once
// `gaia eval` as one call: the paper's emerging properties measured (§5) with the models loaded: action control
// against the counterfactual replay, text control against the guidance scale, diversity of futures and a
// minute-long rollout; then the report: eval.json, plots, videos, and report.json / report.html with, when given,
// the likelihood side from `gaia world eval` and the training curves.
#include <functional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "gaia/emerging/action.h"
#include "gaia/emerging/common.h"
#include "gaia/emerging/rollouts.h"
#include "gaia/emerging/text.h"
#include "gaia/data/episode.h"

namespace gaia::emerging {

struct EvalOptions {
  std::set<std::string> parts{"action", "text", "futures", "long"};
  ActionEvalOptions action;
  TextEvalOptions text;
  RolloutEvalOptions rollouts;       // futures and long
  fs::path world_eval;               // a `gaia world eval` output directory for the report (optional)
  std::vector<std::string> metrics;  // NAME=RUN/metrics.jsonl of training runs: loss curves in the report
  std::vector<std::string> plots;    // extra SVG plots for the report
  nlohmann::json header;             // what eval.json records first (weights, tokens, sampling)
  std::string command_line;          // recorded with every section of the report
};

// The parts of `o` on `ds`'s held-out episodes (with `raw`, the procedural episodes the tokens came from, action
// control compares with the counterfactual replay) into `out`; returns eval.json's content.
nlohmann::json run_eval(Models& m, const world::TokenDataset& ds, const data::Dataset* raw, const EvalOptions& o,
                        const fs::path& out, const std::function<void(int, int, const std::string&)>& progress = {});

// The parts `--only` names ("action,text"), each checked: an unknown one is an error naming it.
std::set<std::string> parse_parts(const std::string& only);

}  // namespace gaia::emerging
