"""The learned success judges: the per-frame judge (`frames`), the video judge (`video`) and the
progress judge (`progress`), what they share (`base`), the videos they learn from and are measured
on (`videos`), their training (`train`, `gymnast train-judge`) and their measurement (`measure`)."""
