// edit_history.cpp - placeholder; its owner fills it in (issue 9: brushes, undo/redo).
