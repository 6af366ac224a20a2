import shutil

shutil.copy2("out1_copy.dat","out1.dat")
shutil.copy2("AOC_obs_copy.txt","AOC_obs.txt")
