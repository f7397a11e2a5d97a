"""Every number of paper 000, paper 001, the data sheets and the standards pamjax uses, each with its source.
Imports nothing."""
