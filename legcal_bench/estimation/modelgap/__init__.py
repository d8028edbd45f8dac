"""The model gap: effects the offsets-only model lacks, their library, confounds and score tests."""
