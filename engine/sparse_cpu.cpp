// sparse_cpu.cpp - placeholder; its owner fills it in (issue 8 item 4 / issue 10).
