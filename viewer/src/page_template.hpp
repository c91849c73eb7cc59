// page_template.hpp — the fixed parts of the viewer page (page_template.cpp): style, body markup
// and the page's script, which reads the JSON block "trellis-data" written by renderView.
#pragma once

namespace trellis {

extern const char* const kViewerStyle;
extern const char* const kViewerBody;
extern const char* const kViewerScript;

}  // namespace trellis
