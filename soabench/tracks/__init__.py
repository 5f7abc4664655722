"""Track metrics of labelled trackers (docs/method.md §9.3): HOTA, CLEAR MOT, IDF1, OSPA(2) and the
re-emergence measures after occlusion, pure functions of per-scan ids and positions."""
