// vdb_io.cpp - placeholder (issue 9 item 4): OpenVDB in and out, mesh export. The only OpenVDB TU besides openvdb_check.cpp.
