"""Allan statistics, the IEEE Std 952 noise-term library and the automatic fit (numpy/scipy only)."""
