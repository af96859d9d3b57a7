// The REST gateway's text checks: UTF-8 validity against RFC 3629's well-formed table (Table 3-7
// of the Unicode standard) written out byte by byte, repair and truncation of echoed input, and
// the request target split and decoded strictly.
#include "server/http_text.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;

TEST(FindInvalidUtf8, AcceptsWellFormedSequencesOfEachLength) {
  EXPECT_EQ(FindInvalidUtf8(""), std::string_view::npos);
  EXPECT_EQ(FindInvalidUtf8("plain ascii"), std::string_view::npos);
  EXPECT_EQ(FindInvalidUtf8("\xC3\xA9"), std::string_view::npos);          // U+00E9
  EXPECT_EQ(FindInvalidUtf8("\xE2\x82\xAC"), std::string_view::npos);      // U+20AC
  EXPECT_EQ(FindInvalidUtf8("\xED\x9F\xBF"), std::string_view::npos);      // U+D7FF
  EXPECT_EQ(FindInvalidUtf8("\xF0\x9F\x98\x80"), std::string_view::npos);  // U+1F600
  EXPECT_EQ(FindInvalidUtf8("\xF4\x8F\xBF\xBF"), std::string_view::npos);  // U+10FFFF
}

TEST(FindInvalidUtf8, FindsTheFirstBadByteOfEachIllFormedKind) {
  EXPECT_EQ(FindInvalidUtf8("ab\xFF"), 2u);            // Never a UTF-8 byte.
  EXPECT_EQ(FindInvalidUtf8("a\x80"), 1u);             // Lone continuation byte.
  EXPECT_EQ(FindInvalidUtf8("a\xC3"), 1u);             // Truncated sequence.
  EXPECT_EQ(FindInvalidUtf8("\xC0\xAF"), 0u);          // Overlong '/'.
  EXPECT_EQ(FindInvalidUtf8("\xE0\x80\xAF"), 0u);      // Overlong '/', 3 bytes.
  EXPECT_EQ(FindInvalidUtf8("x\xED\xA0\x80"), 1u);     // U+D800, a surrogate.
  EXPECT_EQ(FindInvalidUtf8("\xF4\x90\x80\x80"), 0u);  // U+110000, above the range.
  EXPECT_EQ(FindInvalidUtf8(std::string("a\0b", 3)), std::string_view::npos);  // NUL is UTF-8.
}

TEST(Sanitize, ReplacesInvalidBytesAndControlsAndTruncatesOnACharacterBoundary) {
  EXPECT_EQ(Sanitize("ok"), "ok");
  EXPECT_EQ(Sanitize("a\xFF"
                     "b"),
            "a\xEF\xBF\xBD"
            "b");  // U+FFFD.
  EXPECT_EQ(Sanitize("line\nbreak\x7F"), "line?break?");
  // 10 two-byte characters (20 bytes) cut at 5 bytes: 2 characters, not a split third.
  std::string accents;
  for (int i = 0; i < 10; ++i) accents += "\xC3\xA9";
  EXPECT_EQ(Sanitize(accents, 5), "\xC3\xA9\xC3\xA9...");
  EXPECT_EQ(Sanitize(std::string(1000, 'x')).size(), kMaxEchoBytes + 3);
  EXPECT_EQ(FindInvalidUtf8(Sanitize("\xE2\x82")), std::string_view::npos);
}

TEST(ValidUtf8, KeepsValidTextAndRepairsInvalidText) {
  EXPECT_EQ(ValidUtf8("line\nbreak \xC3\xA9"), "line\nbreak \xC3\xA9");
  EXPECT_EQ(ValidUtf8("a\xFF"
                      "b"),
            "a\xEF\xBF\xBD"
            "b");
  // An overlong form and a surrogate: each ill-formed sequence becomes U+FFFD.
  const std::string repaired = ValidUtf8("\xC0\xAF-\xED\xA0\x80");
  EXPECT_EQ(FindInvalidUtf8(repaired), std::string_view::npos);
  EXPECT_THAT(repaired, HasSubstr("\xEF\xBF\xBD-\xEF\xBF\xBD"));
}

TEST(ParseRequestTarget, SplitsAndDecodesPathAndQuery) {
  StatusOr<RequestTarget> t =
      ParseRequestTarget("/v1/operations?filter=kind%3Dsweep+AND+state%3DRUNNING&pageSize=5&flag");
  ASSERT_TRUE(t.ok()) << t.status().ToString();
  EXPECT_EQ(t->path, "/v1/operations");
  EXPECT_TRUE(t->has_query);
  ASSERT_EQ(t->query.size(), 3u);
  EXPECT_EQ(t->query[0].first, "filter");
  EXPECT_EQ(t->query[0].second, "kind=sweep AND state=RUNNING");
  EXPECT_EQ(t->query[1].second, "5");
  EXPECT_EQ(t->query[2].first, "flag");
  EXPECT_EQ(t->query[2].second, "");

  t = ParseRequestTarget("/v1/jobs%3Asimulate");
  ASSERT_TRUE(t.ok());
  EXPECT_EQ(t->path, "/v1/jobs:simulate");
  EXPECT_FALSE(t->has_query);
  // '+' is a plus in the path (form encoding is for queries only); an empty query is a query.
  t = ParseRequestTarget("/a+b?");
  ASSERT_TRUE(t.ok());
  EXPECT_EQ(t->path, "/a+b");
  EXPECT_TRUE(t->has_query);
  EXPECT_TRUE(t->query.empty());
  // Percent-encoded UTF-8 is fine.
  t = ParseRequestTarget("/caf%C3%A9?q=%E2%82%AC");
  ASSERT_TRUE(t.ok());
  EXPECT_EQ(t->path, "/caf\xC3\xA9");
  EXPECT_EQ(t->query[0].second, "\xE2\x82\xAC");
}

TEST(ParseRequestTarget, RefusesBadInputNamingWhere) {
  const auto message = [](std::string_view raw) {
    StatusOr<RequestTarget> t = ParseRequestTarget(raw);
    EXPECT_FALSE(t.ok()) << raw;
    EXPECT_EQ(t.ok() ? StatusCode::kOk : t.status().code(), StatusCode::kInvalidArgument);
    return t.ok() ? std::string() : t.status().message();
  };
  EXPECT_THAT(message("/v1/operations/%FF"), HasSubstr("path: not valid UTF-8"));
  EXPECT_THAT(message("/v1/\xC3"), HasSubstr("path: not valid UTF-8"));
  EXPECT_THAT(message("/v1/a%00b"), HasSubstr("path: a NUL byte"));
  EXPECT_THAT(message("/v1/a%zz"), HasSubstr("path: '%' at byte 5"));
  EXPECT_THAT(message("/v1/a%4"), HasSubstr("two hex digits"));
  EXPECT_THAT(message("/x?filter=%C3%28"), HasSubstr("query parameter 'filter': not valid UTF-8"));
  EXPECT_THAT(message("/x?%FF=1"), HasSubstr("query parameter name: not valid UTF-8"));
  EXPECT_THAT(message("*"), HasSubstr("request target: must start with '/'"));
  EXPECT_THAT(message("http://host/x"), HasSubstr("must start with '/'"));
  // The echoed name of a bad parameter is sanitised (a control character becomes '?').
  EXPECT_THAT(message("/x?a%0Ab=%FF"), HasSubstr("query parameter 'a?b'"));
}

}  // namespace
}  // namespace drillbif::server
