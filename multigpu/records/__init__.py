"""What a run leaves behind, with neither MPI nor GL: timing rows by column name, the running
tally and summary, rank 0's record (CSV, summary.json, mosaics, video, flight file), the output
folder, the record of recoveries and why a run stopped."""
