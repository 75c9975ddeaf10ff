#ifndef NUPMPC_CLIENT_EXAMPLES_PERIOD_TABLE_H_
#define NUPMPC_CLIENT_EXAMPLES_PERIOD_TABLE_H_

// What the API examples print about the cost of each control period (NonlinearSession's
// PeriodReport) and the summary that compares warm-started with cold runs.

#include <cstdio>
#include <string>
#include <vector>

#include "client/nonlinear_session.h"

namespace nupmpc::api_examples {

// Means over the periods from `skip` on (the first periods of a warm run are still
// settling: the first is always cold).
struct PeriodSummary {
  int skip = 0;          // periods left out at the start
  int periods = 0;       // counted
  int first_passes = 0;  // of period 0, whatever `skip`
  double passes_per_period = 0.0;
  // The median is what a typical period costs: a rare degenerate solve that runs to the
  // iteration cap (thousands of passes) moves the mean, not the median.
  double median_passes = 0.0;
  double linearisations_per_period = 0.0;
  double period_ms = 0.0;     // the whole Step(): client linearisation + round trips + solves
  double solve_ms = 0.0;      // the server's solver time alone
  double linearise_ms = 0.0;  // the client's f, h and Jacobians
};
PeriodSummary Summarise(const std::vector<PeriodReport>& reports, int skip);

// One line per period: its linearisations, passes, the server's keep-out linearisations
// and the times, under a header printed once.
void PrintPeriodHeader(std::FILE* out);
void PrintPeriod(std::FILE* out, int period, const PeriodReport& report, const std::string& extra = "");

// "warm: ... cold: ..." with passes and times per period and their ratios.
void PrintWarmVsCold(std::FILE* out, const PeriodSummary& warm, const PeriodSummary& cold);

}  // namespace nupmpc::api_examples

#endif  // NUPMPC_CLIENT_EXAMPLES_PERIOD_TABLE_H_
