#include "sim/lab/lab_html.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <sstream>

#include <cmark-gfm-core-extensions.h>
#include <cmark-gfm.h>

namespace sandtable::sim {
namespace {

constexpr uintmax_t kMaxInlineBytes = uintmax_t{32} << 20;

std::string EscapeHtml(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// The file `src` names under `dir` as a data URI; empty when it is not a readable local PNG.
std::string DataUri(const std::string& src, const std::filesystem::path& dir) {
  namespace fs = std::filesystem;
  if (src.find("://") != std::string::npos || src.rfind("data:", 0) == 0) return "";
  const fs::path path = dir / src;
  if (path.extension() != ".png") return "";
  std::error_code ec;
  const uintmax_t size = fs::file_size(path, ec);
  if (ec || size > kMaxInlineBytes) return "";
  std::ifstream in(path, std::ios::binary);
  if (!in) return "";
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return "data:image/png;base64," + Base64(bytes);
}

}  // namespace

std::string Base64(const std::string& bytes) {
  static const char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = (static_cast<uint8_t>(bytes[i]) << 16) |
                       (static_cast<uint8_t>(bytes[i + 1]) << 8) |
                       static_cast<uint8_t>(bytes[i + 2]);
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (i < bytes.size()) {
    uint32_t v = static_cast<uint8_t>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<uint8_t>(bytes[i + 1]) << 8;
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

Expected<std::string> MarkdownToHtmlPage(const std::string& markdown, const std::string& dir,
                                         const std::string& title) {
  cmark_gfm_core_extensions_ensure_registered();
  std::unique_ptr<cmark_parser, void (*)(cmark_parser*)> parser(cmark_parser_new(CMARK_OPT_DEFAULT),
                                                                cmark_parser_free);
  if (!parser) return InternalError("report.html: cmark-gfm made no parser");
  cmark_syntax_extension* table = cmark_find_syntax_extension("table");
  if (!table || !cmark_parser_attach_syntax_extension(parser.get(), table)) {
    return InternalError("report.html: cmark-gfm has no table extension");
  }
  cmark_parser_feed(parser.get(), markdown.data(), markdown.size());
  std::unique_ptr<cmark_node, void (*)(cmark_node*)> document(cmark_parser_finish(parser.get()),
                                                              cmark_node_free);
  if (!document) return InternalError("report.html: cmark-gfm could not parse the report");
  char* rendered = cmark_render_html(document.get(), CMARK_OPT_DEFAULT,
                                     cmark_parser_get_syntax_extensions(parser.get()));
  if (!rendered) return InternalError("report.html: cmark-gfm rendered nothing");
  std::string body(rendered);
  std::free(rendered);
  // Inline the local images.
  std::string inlined;
  const std::string key = "<img src=\"";
  size_t at = 0;
  while (true) {
    const size_t found = body.find(key, at);
    if (found == std::string::npos) break;
    const size_t start = found + key.size();
    const size_t end = body.find('"', start);
    if (end == std::string::npos) break;
    inlined.append(body, at, start - at);
    const std::string src = body.substr(start, end - start);
    const std::string uri = DataUri(src, dir);
    inlined += uri.empty() ? src : uri;
    at = end;
  }
  inlined.append(body, at, std::string::npos);
  std::ostringstream page;
  page << "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>"
       << EscapeHtml(title) << "</title>\n<style>\n"
       << "body{font-family:sans-serif;max-width:70em;margin:1em auto;padding:0 1em;"
          "line-height:1.4;color:#222}\n"
       << "table{border-collapse:collapse;margin:0.5em 0}\n"
       << "th,td{border:1px solid #bbb;padding:0.2em 0.6em;text-align:left}\n"
       << "th{background:#eee}\nimg{max-width:100%;border:1px solid #ddd;margin:0.2em}\n"
       << "code,pre{background:#f4f4f4}\npre{padding:0.5em;overflow-x:auto}\n"
       << "</style>\n</head>\n<body>\n"
       << inlined << "</body>\n</html>\n";
  return page.str();
}

}  // namespace sandtable::sim
