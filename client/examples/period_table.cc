#include "client/examples/period_table.h"

#include <algorithm>

namespace nupmpc::api_examples {

PeriodSummary Summarise(const std::vector<PeriodReport>& reports, int skip) {
  PeriodSummary s;
  s.skip = skip;
  if (!reports.empty()) s.first_passes = reports.front().passes;
  for (std::size_t i = static_cast<std::size_t>(skip); i < reports.size(); ++i) {
    const PeriodReport& r = reports[i];
    ++s.periods;
    s.passes_per_period += r.passes;
    s.linearisations_per_period += r.linearisations;
    s.period_ms += r.period_ms;
    s.solve_ms += r.solve_ms;
    s.linearise_ms += r.linearise_ms;
  }
  std::vector<int> passes;
  for (std::size_t i = static_cast<std::size_t>(skip); i < reports.size(); ++i) passes.push_back(reports[i].passes);
  if (!passes.empty()) {
    std::sort(passes.begin(), passes.end());
    const std::size_t middle = passes.size() / 2;
    s.median_passes = passes.size() % 2 == 1 ? passes[middle] : 0.5 * (passes[middle - 1] + passes[middle]);
  }
  if (s.periods > 0) {
    for (double* mean :
         {&s.passes_per_period, &s.linearisations_per_period, &s.period_ms, &s.solve_ms, &s.linearise_ms}) {
      *mean /= s.periods;
    }
  }
  return s;
}

void PrintPeriodHeader(std::FILE* out) {
  std::fprintf(out, "%6s %5s %7s %7s %9s %10s %9s %9s  %s\n", "period", "lin", "passes", "ko_lin", "lin_ms", "solve_ms",
               "period_ms", "defect", "");
}

void PrintPeriod(std::FILE* out, int period, const PeriodReport& r, const std::string& extra) {
  std::fprintf(out, "%6d %5d %7d %7d %9.3f %10.3f %9.3f %9.1e  %s\n", period, r.linearisations, r.passes,
               r.keep_out_linearisations, r.linearise_ms, r.solve_ms, r.period_ms, r.model_defect, extra.c_str());
}

void PrintWarmVsCold(std::FILE* out, const PeriodSummary& warm, const PeriodSummary& cold) {
  const auto line = [out](const char* name, const PeriodSummary& s) {
    std::fprintf(out,
                 "%s: first period %d passes; from period %d on (%d periods): %.1f passes (median %.1f), %.2f "
                 "linearisations, %.3f ms per period (solver %.3f ms, client linearisation %.3f ms)\n",
                 name, s.first_passes, s.skip, s.periods, s.passes_per_period, s.median_passes,
                 s.linearisations_per_period, s.period_ms, s.solve_ms, s.linearise_ms);
  };
  line("warm", warm);
  line("cold", cold);
  if (cold.passes_per_period > 0 && cold.median_passes > 0 && cold.period_ms > 0) {
    std::fprintf(out, "warm/cold: passes per period %.2f (medians %.2f), time per period %.2f\n",
                 warm.passes_per_period / cold.passes_per_period, warm.median_passes / cold.median_passes,
                 warm.period_ms / cold.period_ms);
  }
}

}  // namespace nupmpc::api_examples
