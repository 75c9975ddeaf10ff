// The Prometheus text writer against the format, read back by the tests' own strict
// parser (tests/util/prometheus_parse.h), which must also refuse malformed text.
#include "server/observability/prometheus_text.h"

#include <limits>

#include "gtest/gtest.h"
#include "tests/util/prometheus_parse.h"

namespace nupmpc::testing {
namespace {

using server::EscapePrometheusLabelValue;
using server::FormatPrometheusValue;
using server::PrometheusText;

TEST(PrometheusText, LabelValuesAndNumbersAreWrittenAsTheFormatWants) {
  EXPECT_EQ(EscapePrometheusLabelValue("a\"b\\c\nd"), "a\\\"b\\\\c\\nd");
  EXPECT_EQ(FormatPrometheusValue(3), "3");
  EXPECT_EQ(FormatPrometheusValue(0.5), "0.5");
  EXPECT_EQ(FormatPrometheusValue(1e15), "1000000000000000");  // counts: exact, no exponent
  EXPECT_EQ(FormatPrometheusValue(1e20), "1e+20");             // beyond 2^53: not an exact count
  EXPECT_EQ(FormatPrometheusValue(std::numeric_limits<double>::infinity()), "+Inf");
  EXPECT_EQ(FormatPrometheusValue(-std::numeric_limits<double>::infinity()), "-Inf");
  EXPECT_EQ(FormatPrometheusValue(std::numeric_limits<double>::quiet_NaN()), "NaN");
  EXPECT_EQ(FormatPrometheusValue(0.1), "0.10000000000000001");  // round-trips exactly
}

TEST(PrometheusText, AHistogramIsCumulativeWithSumAndCount) {
  PrometheusText out;
  out.Family("x_seconds", "histogram", "A test histogram.\nSecond line \\ here.");
  out.Histogram("x_seconds", {{"kind", "a\"b"}}, {0.001, 1}, {1, 0, 2}, 7.5);
  out.Family("y_total", "counter", "A counter.");
  out.Sample("y_total", {}, 4);
  EXPECT_EQ(out.text(),
            "# HELP x_seconds A test histogram.\\nSecond line \\\\ here.\n"
            "# TYPE x_seconds histogram\n"
            "x_seconds_bucket{kind=\"a\\\"b\",le=\"0.001\"} 1\n"
            "x_seconds_bucket{kind=\"a\\\"b\",le=\"1\"} 1\n"
            "x_seconds_bucket{kind=\"a\\\"b\",le=\"+Inf\"} 3\n"
            "x_seconds_sum{kind=\"a\\\"b\"} 7.5\n"
            "x_seconds_count{kind=\"a\\\"b\"} 3\n"
            "# HELP y_total A counter.\n"
            "# TYPE y_total counter\n"
            "y_total 4\n");
  absl::StatusOr<ParsedMetrics> parsed = ParsePrometheusText(out.text());
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->types.at("x_seconds"), "histogram");
  EXPECT_EQ(parsed->at("y_total"), 4);
  EXPECT_EQ(parsed->at("x_seconds_count{kind=\"a\\\"b\"}"), 3);
}

TEST(PrometheusText, TheTestParserRefusesMalformedText) {
  EXPECT_FALSE(ParsePrometheusText("y_total 4\n").ok());  // no # TYPE
  EXPECT_FALSE(ParsePrometheusText("# TYPE y counter\n# TYPE y gauge\n").ok());
  EXPECT_FALSE(ParsePrometheusText("# TYPE y summary\n").ok());
  EXPECT_FALSE(ParsePrometheusText("# TYPE y counter\ny{a=b} 1\n").ok());
  EXPECT_FALSE(ParsePrometheusText("# TYPE y counter\ny one\n").ok());
  EXPECT_FALSE(ParsePrometheusText("# TYPE h histogram\nh_bucket{le=\"1\"} 2\nh_bucket{le=\"+Inf\"} 1\n").ok());
  EXPECT_FALSE(ParsePrometheusText("# TYPE h histogram\nh_bucket{le=\"1\"} 2\n").ok());
  EXPECT_FALSE(ParsePrometheusText("# TYPE h histogram\nh_bucket{le=\"+Inf\"} 2\nh_sum 1\nh_count 3\n").ok());
  EXPECT_TRUE(ParsePrometheusText("# TYPE h histogram\nh_bucket{le=\"+Inf\"} 3\nh_sum 1\nh_count 3\n").ok());
}

}  // namespace
}  // namespace nupmpc::testing
